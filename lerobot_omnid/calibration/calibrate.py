"""``omnid-calibrate``: calibrate real cameras with OpenCV, in the robot base frame, for OmniD.

Two sub-commands:

- ``omnid-calibrate board``: write a printable image of the calibration board (checkerboard or ChArUco).
- ``omnid-calibrate camera``: intrinsics ``K`` (and distortion) from several images of the board in
  varied poses, then extrinsics ``T_cam_world`` from one image of the board lying at a known pose in
  the robot base frame. The result is added to (or replaces that camera in) a calibration file in the
  schema of :mod:`lerobot_omnid.calibration.rig_file`, ready for ``omnid-attach-calibration``.

Board frame (both kinds): the origin is the first inner corner, the x axis runs along the board's rows
of corners, the y axis along its columns, z = x cross y points into the board (away from the printed
face). On the image written by ``omnid-calibrate board`` the origin is the top-left inner corner, x
points right and y down. A checkerboard's ``--pattern`` counts inner corners (OpenCV's ``patternSize``,
e.g. 9x6, 10x7 squares); the square touching the origin corner diagonally is black, and one count must be
odd and the other even so that the colours fix which corner is the origin (else the board looks the same
turned by 180 degrees and only intrinsics can be calibrated). A ChArUco ``--pattern`` counts squares
(e.g. 7x5, OpenCV >= 4.6 layout); its corner ids fix the origin (corner 0).

The board pose in the robot base frame (``world_T_board``) is given by one of:
``--board-on-table X Y YAW_DEG [Z]`` (board lying face up: origin at (X, Y, Z), board x at YAW_DEG from
the robot's x axis, so with yaw 0 x points forward and y to the robot's right), ``--board-points``
(the origin, the last inner corner along x and the last inner corner along y, measured in the base
frame, e.g. by touching them with the robot's tool centre point), or ``--board-pose FILE`` (JSON/YAML
with a 4x4 ``T_world_board``).

Example::

    omnid-calibrate board --board charuco --pattern 7x5 --square-size 0.04 --marker-size 0.03 \\
        --output board.png
    omnid-calibrate camera --camera front --board charuco --pattern 7x5 --square-size 0.04 \\
        --marker-size 0.03 --intrinsics-images 'calib/front/*.png' \\
        --extrinsics-image calib/front/on_table.png --board-on-table 0.40 0.15 0 --output rig.yaml
"""

from __future__ import annotations

import argparse
import glob
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from lerobot_omnid.calibration.rig_file import (
    image_key,
    load_calibration_file,
    load_calibration_meta,
    read_mapping_file,
    save_calibration_file,
)
from lerobot_omnid.calibration.schema import CalibrationError, CameraCalibration

BOARD_KINDS = ("checkerboard", "charuco")
MIN_INTRINSICS_VIEWS = 4  # images with a detected board needed to estimate K
RECOMMENDED_VIEWS = 10
MIN_CHARUCO_CORNERS = 8  # ChArUco corners needed to use a view
MAX_GOOD_RMS_PX = 1.0  # px: reprojection RMS above this gets a warning
BOARD_POINTS_TOL_M = 0.005  # m: allowed mismatch of measured board corner distances (or 2%)
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
        if self.kind not in BOARD_KINDS:
            raise ValueError(f"board kind must be one of {list(BOARD_KINDS)}, got {self.kind!r}")
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


@dataclass(frozen=True)
class Intrinsics:
    """``K`` (3, 3), OpenCV ``distortion`` (5,) or (0,) for a pinhole fit, reprojection RMS over all views
    and per view (px)."""

    K: np.ndarray
    distortion: np.ndarray
    rms_px: float
    view_rms_px: tuple[float, ...]


def calibrate_intrinsics(detections: Sequence[BoardDetection], pinhole: bool = False) -> Intrinsics:
    """OpenCV ``calibrateCamera`` over board views of one camera.

    Args:
        detections: views of the board, all of one image size.
        pinhole: fit a distortion-free model (distortion fixed to zero): the best pinhole approximation
            of the raw images, for datasets recorded without undistortion.
    """
    if len(detections) < MIN_INTRINSICS_VIEWS:
        raise CalibrationError(
            f"intrinsics: the board was found in {len(detections)} image(s), need at least "
            f"{MIN_INTRINSICS_VIEWS} (better {RECOMMENDED_VIEWS}+, tilted and spread over the image)"
        )
    sizes = {d.image_size for d in detections}
    if len(sizes) > 1:
        raise CalibrationError(f"intrinsics: images of different sizes {sorted(sizes)}; use one resolution")
    height, width = detections[0].image_size
    flags = 0
    if pinhole:
        flags = cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3
    object_points = [d.xyz_board.astype(np.float32) for d in detections]
    image_points = [d.uv_pix.astype(np.float32).reshape(-1, 1, 2) for d in detections]
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(
        object_points, image_points, (width, height), None, None, flags=flags
    )
    view_rms = []
    for obj, img, rvec, tvec in zip(object_points, image_points, rvecs, tvecs, strict=True):
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
        view_rms.append(float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=-1)))))
    return Intrinsics(K, np.zeros(0) if pinhole else dist.ravel()[:5], float(rms), tuple(view_rms))


def estimate_cam_T_world(
    detection: BoardDetection, world_T_board: np.ndarray, K: np.ndarray, distortion: np.ndarray
) -> tuple[np.ndarray, float]:
    """``cam_T_world`` (4, 4) from one view of the board at a known pose, and its reprojection RMS (px).

    ``cam_T_world = cam_T_board @ inv(world_T_board)``, with ``cam_T_board`` from ``solvePnP`` (IPPE for a
    planar target, refined by Levenberg-Marquardt).
    """
    obj = detection.xyz_board.astype(np.float64)
    img = detection.uv_pix.astype(np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, distortion, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise CalibrationError("extrinsics: solvePnP found no board pose")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, distortion, rvec, tvec)
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, distortion)
    rms = float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=-1))))
    cam_T_board = np.eye(4)
    cam_T_board[:3, :3] = cv2.Rodrigues(rvec)[0]
    cam_T_board[:3, 3] = tvec.ravel()
    return cam_T_board @ np.linalg.inv(world_T_board), rms


def world_T_board_on_table(x: float, y: float, yaw_deg: float, z: float = 0.0) -> np.ndarray:
    """Pose of a board lying face up: origin at (x, y, z), board x at ``yaw_deg`` from world x, z down."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    world_T_board = np.eye(4)
    # Columns: board x, board y = z cross x, board z = -world z (into the board, which faces up).
    world_T_board[:3, :3] = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
    world_T_board[:3, 3] = (x, y, z)
    return world_T_board


def world_T_board_from_points(
    origin: Sequence[float], x_end: Sequence[float], y_end: Sequence[float], board: BoardSpec
) -> np.ndarray:
    """Board pose from three measured corners (world frame, metres): the origin, the last inner corner
    along x and the last inner corner along y. Their distances must match the board's geometry."""
    p0, px, py = (np.asarray(p, np.float64) for p in (origin, x_end, y_end))
    nx, ny = board.inner_corners
    for name, point, n in (("x", px, nx), ("y", py, ny)):
        measured, expected = np.linalg.norm(point - p0), (n - 1) * board.square_size
        if abs(measured - expected) > max(BOARD_POINTS_TOL_M, 0.02 * expected):
            raise CalibrationError(
                f"--board-points: the last inner corner along {name} is {measured:.4f} m from the origin, "
                f"expected {expected:.4f} m ({n - 1} squares of {board.square_size} m): check the points"
            )
    x_axis = (px - p0) / np.linalg.norm(px - p0)
    z_axis = np.cross(x_axis, py - p0)
    z_axis /= np.linalg.norm(z_axis)
    angle = math.degrees(math.acos(np.clip(np.dot(x_axis, (py - p0) / np.linalg.norm(py - p0)), -1, 1)))
    if abs(angle - 90.0) > 3.0:
        raise CalibrationError(f"--board-points: the x and y edges make {angle:.1f} degrees, expected 90")
    world_T_board = np.eye(4)
    world_T_board[:3, :3] = np.stack([x_axis, np.cross(z_axis, x_axis), z_axis], axis=1)
    world_T_board[:3, 3] = p0
    return world_T_board


def load_board_pose(path: str | Path) -> np.ndarray:
    """``T_world_board`` (4, 4) from a JSON/YAML file ``{"T_world_board": [[...], ...]}``."""
    data = read_mapping_file(Path(path))
    if "T_world_board" not in data:
        raise CalibrationError(f"board pose file {path}: expected a 'T_world_board' 4x4 matrix")
    # Reuse the rigid-transform validation of the calibration schema.
    dummy_K = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    try:
        calib = CameraCalibration.from_dict(
            {"K": dummy_K, "T_cam_world": data["T_world_board"], "image_size": [1, 1]}, camera=f"{path}"
        )
    except CalibrationError as e:
        raise CalibrationError(str(e).replace(".T_cam_world", ".T_world_board")) from e
    return np.asarray(calib.T_cam_world, np.float64)


@dataclass(frozen=True)
class CameraResult:
    """One camera's calibration and how well it fits (``meta`` goes into the calibration file)."""

    key: str
    calibration: CameraCalibration
    meta: dict

    def summary(self) -> str:
        K = np.asarray(self.calibration.K)
        world_T_cam = np.linalg.inv(np.asarray(self.calibration.T_cam_world))
        centre = ", ".join(f"{v:+.3f}" for v in world_T_cam[:3, 3])
        axis = ", ".join(f"{v:+.2f}" for v in world_T_cam[:3, 2])
        lines = [
            f"{self.key}: {self.calibration.image_size[1]}x{self.calibration.image_size[0]} px, "
            f"fx {K[0, 0]:.1f} fy {K[1, 1]:.1f} cx {K[0, 2]:.1f} cy {K[1, 2]:.1f} px",
            f"  camera centre ({centre}) m in the robot base frame, optical axis ({axis})",
        ]
        if "intrinsics_rms_px" in self.meta:
            views = self.meta["intrinsics_views"]
            lines.append(
                f"  intrinsics: reprojection RMS {self.meta['intrinsics_rms_px']:.3f} px over {views} images"
            )
        lines.append(f"  extrinsics: reprojection RMS {self.meta['extrinsics_rms_px']:.3f} px")
        return "\n".join(lines)


def _read_image(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise CalibrationError(f"{path}: not a readable image")
    return image


def calibrate_camera(
    camera: str,
    board: BoardSpec,
    intrinsics_images: Sequence[Path],
    extrinsics_image: Path,
    world_T_board: np.ndarray,
    pinhole: bool = False,
    intrinsics: CameraCalibration | None = None,
) -> CameraResult:
    """Intrinsics from ``intrinsics_images`` (or reuse ``intrinsics``), then ``T_cam_world`` from one view of
    the board at ``world_T_board``. Shows progress; raises :class:`CalibrationError` naming the image."""
    if board.orientation_ambiguous:
        raise CalibrationError(
            f"--pattern {board.cols}x{board.rows}: a checkerboard with both inner corner counts "
            f"{'odd' if board.cols % 2 else 'even'} looks the same turned by 180 degrees, so its pose is "
            f"ambiguous; use one odd and one even count (e.g. 9x6) or a ChArUco board"
        )
    key = image_key(camera)
    meta: dict = {"tool": "omnid-calibrate", "board": board.describe()}
    if intrinsics is None:
        detections, used, missed = [], [], []
        for path in tqdm(intrinsics_images, desc=f"{camera}: finding the board", unit="image"):
            found = detect_board(_read_image(path), board)
            if found is None:
                missed.append(path)
            else:
                detections.append(found)
                used.append(path)
        if missed:
            print(f"{camera}: no board found in {len(missed)} image(s): {', '.join(map(str, missed[:5]))}")
        result = calibrate_intrinsics(detections, pinhole=pinhole)
        K, distortion, image_size = result.K, result.distortion, detections[0].image_size
        meta.update(intrinsics_views=len(detections), intrinsics_rms_px=result.rms_px, pinhole_fit=pinhole)
        worst = int(np.argmax(result.view_rms_px))
        if result.rms_px > MAX_GOOD_RMS_PX:
            print(
                f"warning: {camera}: intrinsics reprojection RMS {result.rms_px:.2f} px is high (worst: "
                f"{used[worst]}, {result.view_rms_px[worst]:.2f} px); check focus, motion blur and the "
                f"board's flatness"
            )
    else:
        K, image_size = np.asarray(intrinsics.K), intrinsics.image_size
        distortion = np.asarray(intrinsics.distortion, np.float64)
        meta["intrinsics"] = "reused"
    detection = detect_board(_read_image(extrinsics_image), board)
    if detection is None:
        needed = "every inner corner" if board.kind == "checkerboard" else f"{MIN_CHARUCO_CORNERS}+ corners"
        raise CalibrationError(f"{extrinsics_image}: the board was not found ({needed} must be visible)")
    if detection.image_size != tuple(image_size):
        raise CalibrationError(
            f"{extrinsics_image}: image size {detection.image_size} (h, w) differs from the intrinsics' "
            f"{tuple(image_size)}"
        )
    cam_T_world, rms = estimate_cam_T_world(detection, world_T_board, K, distortion)
    meta["extrinsics_rms_px"] = rms
    if rms > MAX_GOOD_RMS_PX:
        print(f"warning: {camera}: extrinsics reprojection RMS {rms:.2f} px is high ({extrinsics_image})")
    centre_world = np.linalg.inv(cam_T_world)[:3, 3]
    if centre_world[2] < 0:
        print(
            f"warning: {camera}: the camera comes out {-centre_world[2]:.2f} m below the table top; check "
            f"the board pose (the board's z axis points into the board: down for a board lying face up)"
        )
    calibration = CameraCalibration.from_dict(
        {
            "K": K.tolist(),
            "T_cam_world": cam_T_world.tolist(),
            "image_size": [int(image_size[0]), int(image_size[1])],
            "distortion": [float(v) for v in distortion],
        },
        camera=key,
    )
    return CameraResult(key, calibration, meta)


def _expand(patterns: Sequence[str]) -> list[Path]:
    paths: list[Path] = []
    for pattern in patterns:
        matches = sorted(glob.glob(pattern)) if glob.has_magic(pattern) else [pattern]
        if not matches:
            raise CalibrationError(f"--intrinsics-images: {pattern!r} matches no file")
        paths.extend(Path(m) for m in matches)
    return paths


def _pattern(value: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in value.lower().split("x"))
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"expected COLSxROWS such as 9x6, got {value!r}") from e
    return cols, rows


def _add_board_args(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("board")
    group.add_argument("--board", choices=BOARD_KINDS, required=True, help="board kind")
    group.add_argument(
        "--pattern",
        type=_pattern,
        required=True,
        help="checkerboard: inner corners COLSxROWS (e.g. 9x6); charuco: squares COLSxROWS (e.g. 7x5)",
    )
    group.add_argument("--square-size", type=float, required=True, help="square side, metres")
    group.add_argument("--marker-size", type=float, help="ChArUco marker side, metres")
    group.add_argument(
        "--dictionary", default="DICT_5X5_100", help="ChArUco dictionary (default: %(default)s)"
    )


def _board(args: argparse.Namespace) -> BoardSpec:
    cols, rows = args.pattern
    return BoardSpec(args.board, cols, rows, args.square_size, args.marker_size, args.dictionary)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnid-calibrate",
        description="Calibrate cameras (intrinsics and extrinsics in the robot base frame) for OmniD.",
        epilog="See the module docstring of lerobot_omnid.calibration.calibrate for the board frame.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    board = sub.add_parser("board", help="write a printable board image")
    _add_board_args(board)
    board.add_argument(
        "--px-per-square", type=int, default=200, help="pixels per square (default: %(default)s)"
    )
    board.add_argument("--output", type=Path, required=True, help="image file to write (PNG)")

    cam = sub.add_parser("camera", help="calibrate one camera and add it to a calibration file")
    cam.add_argument("--camera", required=True, help="camera name or feature key (observation.images.<cam>)")
    _add_board_args(cam)
    cam.add_argument(
        "--intrinsics-images", nargs="+", help="images (or quoted globs) of the board in varied poses"
    )
    cam.add_argument(
        "--intrinsics-from",
        type=Path,
        help="reuse this camera's K and distortion from a calibration file (e.g. after the camera moved)",
    )
    cam.add_argument(
        "--pinhole",
        action="store_true",
        help="fit K with distortion fixed to zero (best pinhole model of raw, not undistorted images)",
    )
    cam.add_argument(
        "--extrinsics-image", type=Path, required=True, help="image of the board at its known pose"
    )
    pose = cam.add_mutually_exclusive_group(required=True)
    pose.add_argument(
        "--board-on-table",
        nargs="+",
        type=float,
        metavar="X Y YAW_DEG [Z]",
        help="board lying face up: origin at (X, Y, Z=0) m, its x axis at YAW_DEG from the robot's x axis",
    )
    pose.add_argument(
        "--board-points",
        nargs=9,
        type=float,
        metavar="V",
        help="x y z of the origin, of the last inner corner along x, of the last inner corner along y (m)",
    )
    pose.add_argument("--board-pose", type=Path, help="JSON/YAML file with a 4x4 T_world_board")
    cam.add_argument("--output", type=Path, required=True, help="calibration file to create or update")
    return parser


def _world_T_board(args: argparse.Namespace, board: BoardSpec) -> np.ndarray:
    if args.board_pose is not None:
        return load_board_pose(args.board_pose)
    if args.board_points is not None:
        p = args.board_points
        return world_T_board_from_points(p[0:3], p[3:6], p[6:9], board)
    if len(args.board_on_table) not in (3, 4):
        raise CalibrationError(f"--board-on-table: expected X Y YAW_DEG [Z], got {args.board_on_table}")
    return world_T_board_on_table(*args.board_on_table)


def run_camera(args: argparse.Namespace) -> CameraResult:
    board = _board(args)
    if (args.intrinsics_images is None) == (args.intrinsics_from is None):
        raise CalibrationError("give exactly one of --intrinsics-images and --intrinsics-from")
    intrinsics = None
    if args.intrinsics_from is not None:
        known = load_calibration_file(args.intrinsics_from)
        key = image_key(args.camera)
        if key not in known:
            raise CalibrationError(
                f"--intrinsics-from {args.intrinsics_from}: no camera {key} (has {sorted(known)})"
            )
        intrinsics = known[key]
    world_T_board = _world_T_board(args, board)
    result = calibrate_camera(
        args.camera,
        board,
        _expand(args.intrinsics_images or []),
        args.extrinsics_image,
        world_T_board,
        pinhole=args.pinhole,
        intrinsics=intrinsics,
    )
    calibrations, meta = {}, {}
    if args.output.exists():
        calibrations = load_calibration_file(args.output)
        meta = load_calibration_meta(args.output)
    calibrations[result.key] = result.calibration
    meta[result.key] = result.meta
    save_calibration_file(args.output, calibrations, meta)
    return result


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "board":
            board = _board(args)
            image = board_image(board, args.px_per_square)
            if not cv2.imwrite(str(args.output), image):
                raise CalibrationError(f"--output {args.output}: could not write the image")
            nx, ny = board.inner_corners
            width_mm = image.shape[1] / args.px_per_square * board.square_size * 1000
            print(
                f"wrote {args.output}: {board.describe()}; print it {width_mm:.0f} mm wide (check that a "
                f"square measures {board.square_size * 1000:g} mm); origin at the top-left inner corner, "
                f"{nx}x{ny} inner corners"
            )
            return 0
        result = run_camera(args)
    except (CalibrationError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(result.summary())
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
