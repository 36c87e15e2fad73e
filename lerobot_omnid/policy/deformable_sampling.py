"""Parameter-free multi-camera deformable sampling: bilinear samples summed with attention weights.

This is the only place where image features are gathered at learned locations. It is pure PyTorch
(``grid_sample``), so it runs on CPU and GPU. A faster kernel may replace it and must match it
(``tests/policy/test_deformable_sampling.py``).

Memory: the naive formulation materialises B*S*heads*Q*N*Dh sampled values (B batch, S cameras,
Q queries, N samples per query, Dh channels per head) before the weighted sum. We process queries in
chunks; in training each chunk runs under activation checkpointing, so only one chunk's samples are
alive at a time and the backward pass recomputes them. The peak then scales with ``query_chunk_size``
instead of Q.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor
from torch.utils.checkpoint import checkpoint


def _sample_chunk(values: Tensor, grid: Tensor, weights: Tensor) -> Tensor:
    """values (X, Dh, H, W), grid (X, Qc, N, 2), weights (X, Qc, N) -> (X, Dh, Qc); X = B*S*heads."""
    sampled = F.grid_sample(values, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    # X, Dh, Qc, N  *  X, 1, Qc, N  -> (sum over N) X, Dh, Qc. An elementwise product and a reduction
    # over the contiguous last axis: einsum would turn this into X*Qc tiny matrix products.
    return (sampled * weights[:, None]).sum(dim=-1)


def multi_camera_deformable_sampling(
    values: Tensor,
    sampling_grid: Tensor,
    attention_weights: Tensor,
    query_chunk_size: int | None = None,
    use_checkpoint: bool = False,
) -> Tensor:
    """Sum over cameras and samples of ``weight * Bilinear(values, location)``.

    Args:
        values: (B, S, heads, Dh, H, W) per-camera feature maps split into heads.
        sampling_grid: (B, S, Q, heads, N, 2) sampling locations in ``grid_sample`` coordinates
            ([-1, 1], ``align_corners=False``); samples outside contribute zero.
        attention_weights: (B, S, Q, heads, N), already normalised (and zero where masked).
        query_chunk_size: process this many queries at a time (None: all at once).
        use_checkpoint: recompute each chunk's samples in the backward pass instead of storing them.
    Returns:
        (B, Q, heads * Dh) fused features.
    """
    B, S, heads, Dh, H, W = values.shape
    Q, N = sampling_grid.shape[2], sampling_grid.shape[4]
    if sampling_grid.shape != (B, S, Q, heads, N, 2):
        raise ValueError(
            f"sampling_grid: expected shape {(B, S, Q, heads, N, 2)}, got {tuple(sampling_grid.shape)}"
        )
    if attention_weights.shape != (B, S, Q, heads, N):
        raise ValueError(
            f"attention_weights: expected shape {(B, S, Q, heads, N)}, got {tuple(attention_weights.shape)}"
        )

    # Under mixed precision the locations stay in full precision (a bf16 grid coordinate is off by up to
    # a pixel per 128 of image width): sample in the wider of the two dtypes.
    dtype = torch.promote_types(values.dtype, sampling_grid.dtype)
    values, sampling_grid, attention_weights = (
        t.to(dtype) for t in (values, sampling_grid, attention_weights)
    )
    # B, S, heads, Dh, H, W -> B*S*heads, Dh, H, W
    flat_values = values.reshape(B * S * heads, Dh, H, W)
    # B, S, Q, heads, N, 2 -> B, S, heads, Q, N, 2 -> B*S*heads, Q, N, 2
    flat_grid = sampling_grid.permute(0, 1, 3, 2, 4, 5).reshape(B * S * heads, Q, N, 2)
    # B, S, Q, heads, N -> B*S*heads, Q, N
    flat_weights = attention_weights.permute(0, 1, 3, 2, 4).reshape(B * S * heads, Q, N)

    chunk = query_chunk_size or Q
    outputs = []
    for start in range(0, Q, chunk):
        grid_c = flat_grid[:, start : start + chunk]
        weights_c = flat_weights[:, start : start + chunk]
        if use_checkpoint and torch.is_grad_enabled():
            outputs.append(checkpoint(_sample_chunk, flat_values, grid_c, weights_c, use_reentrant=False))
        else:
            outputs.append(_sample_chunk(flat_values, grid_c, weights_c))
    fused = torch.cat(outputs, dim=-1)  # B*S*heads, Dh, Q
    # B*S*heads, Dh, Q -> B, S, heads, Dh, Q -> (sum over cameras) B, heads, Dh, Q -> B, Q, heads*Dh
    fused = fused.reshape(B, S, heads, Dh, Q).sum(dim=1)
    return fused.permute(0, 3, 1, 2).reshape(B, Q, heads * Dh)
