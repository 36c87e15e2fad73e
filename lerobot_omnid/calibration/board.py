"""Calibration boards (checkerboard or ChArUco): their geometry, a printable image, and their detection.

Board frame: the origin is the first inner corner, the x axis runs along the board's rows of corners, the
y axis along its columns, z = x cross y points into the board (away from the printed face); see
:mod:`lerobot_omnid.calibration.calibrate` for how the board's pose is given.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lerobot_omnid.cli import check_choice

BOARD_KINDS = ("checkerboard", "charuco")
MIN_CHARUCO_CORNERS = 8  # ChArUco corners needed to use a view
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)


@dataclass(frozen=True)
class BoardSpec:
    """A calibration board.

    Args:
        kind: "checkerboard" or "charuco".
        cols, rows: checkerboard: inner corners along x and y; ChArUco: squares along x and y.
        square_size: side of one square, metres.
        marker_size: ChArUco marker side, metres (smaller than ``square_size``).
        dictionary: ChArUco ArUco dictionary name (``cv2.aruco.DICT_*``).
    """

    kind: str
    cols: int
    rows: int
    square_size: float
    marker_size: float | None = None
    dictionary: str = "DICT_5X5_100"

    def __post_init__(self) -> None:
        check_choice("kind", self.kind, BOARD_KINDS)
        low = 2 if self.kind == "checkerboard" else 3
        if self.cols < low or self.rows < low:
            raise ValueError(
                f"--pattern: {self.kind} needs at least {low}x{low}, got {self.cols}x{self.rows}"
            )
        if not self.square_size > 0:
            raise ValueError(f"--square-size must be > 0 metres, got {self.square_size}")
        if self.kind == "charuco":
            if self.marker_size is None or not 0 < self.marker_size < self.square_size:
                raise ValueError(
                    f"--marker-size: ChArUco markers must be > 0 and smaller than the squares "
                    f"({self.square_size} m), got {self.marker_size}"
                )
            if not hasattr(cv2.aruco, self.dictionary) or not self.dictionary.startswith("DICT_"):
                raise ValueError(f"--dictionary: unknown ArUco dictionary {self.dictionary!r}")

    @property
    def inner_corners(self) -> tuple[int, int]:
        """Inner corners along x and y."""
        return (self.cols, self.rows) if self.kind == "checkerboard" else (self.cols - 1, self.rows - 1)

    @property
    def orientation_ambiguous(self) -> bool:
        """Whether the board looks the same turned by 180 degrees (checkerboard, counts of one parity)."""
        return self.kind == "checkerboard" and (self.cols + self.rows) % 2 == 0

    def object_points(self) -> np.ndarray:
        """(N, 3) inner corners in the board frame, row by row (ChArUco: in corner id order)."""
        nx, ny = self.inner_corners
        ys, xs = np.mgrid[0:ny, 0:nx]
        return np.stack([xs.ravel(), ys.ravel(), np.zeros(nx * ny)], axis=1) * self.square_size

    def charuco_board(self) -> cv2.aruco.CharucoBoard:
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square_size, self.marker_size, dictionary)

    def describe(self) -> str:
        size = f"{self.square_size * 1000:g} mm squares"
        if self.kind == "charuco":
            marker = f"{self.marker_size * 1000:g} mm {self.dictionary} markers"
            return f"charuco {self.cols}x{self.rows} squares, {size}, {marker}"
        return f"checkerboard {self.cols}x{self.rows} inner corners, {size}"


def board_image(board: BoardSpec, px_per_square: int = 100, margin_px: int | None = None) -> np.ndarray:
    """Printable (H, W) uint8 image of ``board``, white margin included.

    The board's origin (first inner corner) lies at pixel ``margin + px_per_square - 0.5`` in both
    directions (pixel centres at integers), x right and y down; the image spans
    ``(squares + 2 margin / px_per_square) * square_size`` metres when printed at scale.
    """
    margin = px_per_square // 2 if margin_px is None else margin_px
    nx, ny = board.inner_corners
    squares_x, squares_y = nx + 1, ny + 1
    size = (squares_x * px_per_square + 2 * margin, squares_y * px_per_square + 2 * margin)  # (w, h)
    if board.kind == "charuco":
        return board.charuco_board().generateImage(size, marginSize=margin, borderBits=1)
    image = np.full((size[1], size[0]), 255, np.uint8)
    for j in range(squares_y):
        for i in range(squares_x):
            if (i + j) % 2 == 0:
                y0, x0 = margin + j * px_per_square, margin + i * px_per_square
                image[y0 : y0 + px_per_square, x0 : x0 + px_per_square] = 0
    return image


@dataclass(frozen=True)
class BoardDetection:
    """Board corners found in one image: ``uv_pix`` (N, 2) and ``xyz_board`` (N, 3), ``image_size`` (h, w)."""

    uv_pix: np.ndarray
    xyz_board: np.ndarray
    image_size: tuple[int, int]


def _gray(image: np.ndarray) -> np.ndarray:
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def _canonical_checkerboard(corners: np.ndarray, gray: np.ndarray, board: BoardSpec) -> np.ndarray:
    """Reorder detected corners (ny, nx, 2) so that they follow the board frame of the module docstring.

    OpenCV may return the grid in any of its symmetric orders. A view of the printed face keeps the
    board's handedness (x right, y down gives a positive cross product in u-right, v-down pixels):
    flip the rows when it does not. Then the interior squares whose indices sum to an even number must
    be the dark ones; turn the grid by 180 degrees when they are not (this needs nx + ny odd).
    """
    x_dir = (corners[:, -1] - corners[:, 0]).mean(axis=0)
    y_dir = (corners[-1, :] - corners[0, :]).mean(axis=0)
    if x_dir[0] * y_dir[1] - x_dir[1] * y_dir[0] < 0:
        corners = corners[::-1]
    if board.orientation_ambiguous:
        return corners
    centres = (corners[:-1, :-1] + corners[:-1, 1:] + corners[1:, :-1] + corners[1:, 1:]) / 4
    values = np.array(
        [cv2.getRectSubPix(gray, (3, 3), tuple(map(float, c))).mean() for c in centres.reshape(-1, 2)]
    )
    jj, ii = np.mgrid[1 : corners.shape[0], 1 : corners.shape[1]]
    dark = ((ii + jj) % 2 == 0).ravel()
    if values[dark].mean() > values[~dark].mean():
        corners = corners[::-1, ::-1]
    return corners


def detect_board(image: np.ndarray, board: BoardSpec) -> BoardDetection | None:
    """Find ``board`` in an image (BGR or gray uint8); None when it is not (fully) found."""
    gray = _gray(image)
    size = gray.shape[:2]
    if board.kind == "charuco":
        charuco = board.charuco_board()
        corners, ids, _, _ = cv2.aruco.CharucoDetector(charuco).detectBoard(gray)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return None
        ids = ids.ravel()
        xyz = np.asarray(charuco.getChessboardCorners(), np.float64)
        xyz = xyz - xyz[0]
        return BoardDetection(corners.reshape(-1, 2).astype(np.float64), xyz[ids], size)
    nx, ny = board.inner_corners
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, (nx, ny), flags=flags)
    if not found:
        return None
    grid = corners.reshape(ny, nx, 2)
    spacing = min(
        np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
        np.linalg.norm(np.diff(grid, axis=1), axis=-1).min(),
    )
    half_window = int(np.clip(spacing * 0.4, 2, 11))
    corners = cv2.cornerSubPix(gray, corners, (half_window, half_window), (-1, -1), SUBPIX_CRITERIA)
    grid = _canonical_checkerboard(corners.reshape(ny, nx, 2).astype(np.float64), gray, board)
    return BoardDetection(grid.reshape(-1, 2), board.object_points(), size)
