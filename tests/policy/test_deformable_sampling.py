"""The sampler against an explicit bilinear reference; chunking and checkpointing change nothing."""

import torch

from lerobot_omnid.policy.deformable_sampling import multi_camera_deformable_sampling


def bilinear_reference(image: torch.Tensor, x: float, y: float) -> torch.Tensor:
    """image (C, H, W); (x, y) in grid coordinates (align_corners=False), zero outside."""
    C, H, W = image.shape
    u, v = (x + 1) * W / 2 - 0.5, (y + 1) * H / 2 - 0.5
    u0, v0 = int(torch.floor(torch.tensor(u))), int(torch.floor(torch.tensor(v)))
    out = torch.zeros(C)
    for du in (0, 1):
        for dv in (0, 1):
            ui, vi = u0 + du, v0 + dv
            w = (1 - abs(u - ui)) * (1 - abs(v - vi))
            if 0 <= ui < W and 0 <= vi < H:
                out += w * image[:, vi, ui]
    return out


def random_inputs(B=2, S=3, heads=2, Dh=4, H=5, W=7, Q=6, N=3, seed=0):
    g = torch.Generator().manual_seed(seed)
    values = torch.randn(B, S, heads, Dh, H, W, generator=g)
    grid = torch.rand(B, S, Q, heads, N, 2, generator=g) * 2.4 - 1.2  # some samples fall outside
    weights = torch.rand(B, S, Q, heads, N, generator=g)
    return values, grid, weights


def test_matches_explicit_bilinear_sum():
    values, grid, weights = random_inputs()
    out = multi_camera_deformable_sampling(values, grid, weights)
    B, S, heads, Dh = values.shape[:4]
    Q, N = grid.shape[2], grid.shape[4]
    expected = torch.zeros(B, Q, heads, Dh)
    for b in range(B):
        for q in range(Q):
            for h in range(heads):
                for s in range(S):
                    for n in range(N):
                        x, y = grid[b, s, q, h, n].tolist()
                        expected[b, q, h] += weights[b, s, q, h, n] * bilinear_reference(
                            values[b, s, h], x, y
                        )
    assert torch.allclose(out, expected.reshape(B, Q, heads * Dh), atol=1e-5)


def test_chunking_and_checkpointing_give_same_values_and_gradients():
    values, grid, weights = random_inputs(Q=11)
    results = []
    for chunk, ckpt in [(None, False), (4, False), (4, True), (1, True)]:
        v, g, w = (t.clone().requires_grad_(True) for t in (values, grid, weights))
        out = multi_camera_deformable_sampling(v, g, w, query_chunk_size=chunk, use_checkpoint=ckpt)
        (out * torch.linspace(-1, 1, out.numel()).view_as(out)).sum().backward()
        results.append((out.detach(), v.grad, g.grad, w.grad))
    for other in results[1:]:
        for a, b in zip(results[0], other, strict=True):
            assert torch.allclose(a, b, atol=1e-5)
