"""Procedural table-top textures: the ID wood and four OOD backgrounds, generated in numpy.

Every texture is a deterministic function of its name and size: (size, size, 3) uint8 RGB.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType

import numpy as np

NOISE_TEXTURE_SEED = 20240611  # fixed seed of the OOD3 noise pattern (content, not episode randomness)
CHECKER_CELLS = 8  # squares per side of the OOD1 checkerboard
STRIPE_PERIOD = 16  # px: period of the OOD4 stripes
NOISE_CELL = 4  # px: size of one OOD3 noise cell before smoothing


def _grid(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised pixel coordinates (rows, cols) in [0, 1), each (size, size)."""
    axis = np.arange(size, dtype=np.float64) / size
    return np.meshgrid(axis, axis, indexing="ij")


def _mix(a: tuple[float, float, float], b: tuple[float, float, float], t: np.ndarray) -> np.ndarray:
    """Blend two RGB colours (0..255) with weights ``t`` (size, size) in [0, 1] -> uint8 image."""
    a_arr, b_arr = np.asarray(a), np.asarray(b)
    img = a_arr * (1.0 - t[..., None]) + b_arr * t[..., None]
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def wood(size: int) -> np.ndarray:
    """ID background: light wood with soft sinusoidal grain."""
    rows, cols = _grid(size)
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * (18 * rows + 1.5 * np.sin(2 * np.pi * 2 * cols)))
    return _mix((196, 160, 118), (172, 132, 92), 0.6 * grain)


def checker(size: int) -> np.ndarray:
    """OOD1: navy and white checkerboard."""
    rows, cols = _grid(size)
    t = ((np.floor(rows * CHECKER_CELLS) + np.floor(cols * CHECKER_CELLS)) % 2).astype(np.float64)
    return _mix((235, 235, 240), (30, 45, 110), t)


def gradient(size: int) -> np.ndarray:
    """OOD2: diagonal gradient from teal to magenta."""
    rows, cols = _grid(size)
    return _mix((20, 160, 150), (190, 40, 150), (rows + cols) / 2.0)


def noise(size: int) -> np.ndarray:
    """OOD3: smoothed green-grey value noise (fixed seed)."""
    rng = np.random.default_rng(NOISE_TEXTURE_SEED)
    cells = -(-size // NOISE_CELL)
    coarse = rng.random((cells, cells))
    fine = np.kron(coarse, np.ones((NOISE_CELL, NOISE_CELL)))[:size, :size]
    # Box-blur once along each axis so the cells read as blotches, not pixels.
    kernel = np.ones(NOISE_CELL) / NOISE_CELL
    fine = np.apply_along_axis(lambda r: np.convolve(r, kernel, mode="same"), 0, fine)
    fine = np.apply_along_axis(lambda r: np.convolve(r, kernel, mode="same"), 1, fine)
    fine = (fine - fine.min()) / max(fine.max() - fine.min(), 1e-9)
    return _mix((40, 70, 40), (170, 200, 150), fine)


def stripes(size: int) -> np.ndarray:
    """OOD4: diagonal red and yellow stripes."""
    rows, cols = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    t = (((rows + cols) // (STRIPE_PERIOD // 2)) % 2).astype(np.float64)
    return _mix((200, 40, 35), (240, 210, 60), t)


BACKGROUND_TEXTURES: Mapping[str, Callable[[int], np.ndarray]] = MappingProxyType(
    {
        "id": wood,
        "ood1": checker,
        "ood2": gradient,
        "ood3": noise,
        "ood4": stripes,
    }
)
