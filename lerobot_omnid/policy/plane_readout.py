"""How the OFG's bird's-eye plane becomes the diffusion head's image condition (``config.plane_readout``).

Shape legend: B batch, Q plane queries (row-major over the plane, Na x Nb cells), D d_model, c compressed
channels, F ``readout_dim``, L ``readout_latents``.

- ``flatten`` (the paper's): every query's compressed channels, Q * c values.
- ``keypoints``: one soft-argmax keypoint per compressed channel, a position on the plane, 2c values. A
  softmax ignores a constant shift, so the keypoint says where a channel fires, not whether or how much;
  two peaks average to their midpoint.
- ``keypoint_features``: the keypoint, the plane feature under the channel's softmax (projected to F
  values) and a presence logit (the channel's logsumexp over the plane, which grows with how strongly it
  fires anywhere), c * (3 + F) values.
- ``latent_queries``: L learned queries attend over the plane tokens (their features and plane
  positions), L * F values: they can pick several objects, their extent and their features.
- ``bev_conv``: a small strided CNN over the compressed plane as an image with two coordinate channels,
  F * 8 values: local shape and position kept by the convolution's layout.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

PLANE_READOUTS = ("flatten", "keypoints", "keypoint_features", "latent_queries", "bev_conv")
BEV_CONV_WIDTH = 32  # channels of the bev_conv readout's hidden layers
BEV_CONV_OUT_MULTIPLE = 8  # bev_conv's condition has readout_dim * this many values


def plane_keypoints(compressed: Tensor, plane_xy: Tensor) -> Tensor:
    """Each channel's softmax over the plane, and the expected plane position under it (a spatial soft-argmax
    on the bird's-eye plane: positions in the base frame, not in any image).

    Args:
        compressed: (B, Q, c) channel-compressed plane.
        plane_xy: (Q, 2) each query's position on the plane, normalised to [-1, 1] within the volume.
    Returns:
        (B, c, 2) one keypoint per channel, in the coordinates of ``plane_xy``.
    """
    return torch.einsum("bqc,qk->bck", compressed.softmax(dim=1), plane_xy)


class KeypointFeatureReadout(nn.Module):
    """Per compressed channel: its keypoint, the plane feature under its softmax and a presence logit."""

    def __init__(self, d_model: int, channels: int, feature_dim: int) -> None:
        super().__init__()
        self.feature = nn.Linear(d_model, feature_dim)
        self.out_dim = channels * (3 + feature_dim)

    def forward(self, plane: Tensor, compressed: Tensor, plane_xy: Tensor) -> Tensor:
        """plane (B, Q, D), compressed (B, Q, c), plane_xy (Q, 2) -> (B, c * (3 + F))."""
        weights = compressed.softmax(dim=1)  # B, Q, c
        keypoints = torch.einsum("bqc,qk->bck", weights, plane_xy)  # B, c, 2
        features = self.feature(torch.einsum("bqc,bqd->bcd", weights, plane))  # B, c, D -> B, c, F
        presence = compressed.logsumexp(dim=1)[..., None]  # B, c, 1
        return torch.cat([keypoints, features, presence], dim=-1).flatten(1)


class LatentQueryReadout(nn.Module):
    """L learned queries cross-attend over the plane tokens; each gives F values."""

    def __init__(self, d_model: int, num_heads: int, num_latents: int, feature_dim: int) -> None:
        super().__init__()
        self.latents = nn.Parameter(torch.randn(num_latents, d_model) * 0.02)
        self.position = nn.Linear(2, d_model)
        self.attention = nn.MultiheadAttention(d_model, num_heads, batch_first=True)
        self.out = nn.Linear(d_model, feature_dim)
        self.out_dim = num_latents * feature_dim

    def forward(self, plane: Tensor, compressed: Tensor, plane_xy: Tensor) -> Tensor:
        """plane (B, Q, D), plane_xy (Q, 2) -> (B, L * F)."""
        tokens = plane + self.position(plane_xy)  # B, Q, D
        queries = self.latents.expand(plane.shape[0], -1, -1)  # B, L, D
        attended, _ = self.attention(queries, tokens, tokens, need_weights=False)
        return self.out(attended).flatten(1)  # B, L, F -> B, L*F


class BEVConvReadout(nn.Module):
    """Two stride-2 3x3 convolutions over the compressed plane plus coordinate channels, then a linear map."""

    def __init__(self, channels: int, plane_shape: tuple[int, int], feature_dim: int) -> None:
        super().__init__()
        self.plane_shape = plane_shape
        self.net = nn.Sequential(
            nn.Conv2d(channels + 2, BEV_CONV_WIDTH, 3, stride=2, padding=1),
            nn.ReLU(),
            nn.Conv2d(BEV_CONV_WIDTH, BEV_CONV_WIDTH, 3, stride=2, padding=1),
            nn.ReLU(),
            nn.Flatten(),
        )
        cells = ((plane_shape[0] + 3) // 4) * ((plane_shape[1] + 3) // 4)  # after two stride-2 convs
        self.out_dim = feature_dim * BEV_CONV_OUT_MULTIPLE
        self.out = nn.Linear(BEV_CONV_WIDTH * cells, self.out_dim)

    def forward(self, plane: Tensor, compressed: Tensor, plane_xy: Tensor) -> Tensor:
        """compressed (B, Q, c), plane_xy (Q, 2) -> (B, F * 8)."""
        B = compressed.shape[0]
        na, nb = self.plane_shape
        # B, Q, c (+ Q, 2 coordinates) -> B, Q, c+2 -> B, c+2, Na, Nb
        x = torch.cat([compressed, plane_xy.expand(B, -1, -1)], dim=-1).transpose(1, 2).reshape(B, -1, na, nb)
        return self.out(self.net(x))
