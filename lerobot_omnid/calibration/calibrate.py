"""``omnid-calibrate``: calibrate real cameras with OpenCV, in the robot base frame, for OmniD.

Three sub-commands:

- ``omnid-calibrate board``: write a printable image of the calibration board (checkerboard or ChArUco).
- ``omnid-calibrate camera``: intrinsics ``K`` (and distortion) from several images of the board in
  varied poses, then extrinsics ``T_cam_world`` from one image of the board lying at a known pose in
  the robot base frame. The result is added to (or replaces that camera in) a calibration file in the
  schema of :mod:`lerobot_omnid.calibration.rig_file`, ready for ``omnid-attach-calibration``.
- ``omnid-calibrate hand-eye``: a camera on the gripper (eye-in-hand). Images of a board fixed anywhere
  in the scene, taken at several robot poses, and the gripper's pose ``T_base_gripper`` for each (a
  gripper poses file); intrinsics as for ``camera`` (or reused), the board's pose in each image
  (``solvePnP``), then ``T_gripper_cam`` (camera frame -> gripper frame) with ``cv2.calibrateHandEye``.
  The result is added to (or replaces that camera in) a hand-eye file; both files' schemas and the
  per-frame extrinsics ``T_cam_world(t) = inv(T_base_gripper(t) @ T_gripper_cam)`` are in
  :mod:`lerobot_omnid.calibration.hand_eye`.

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
    omnid-calibrate hand-eye --camera wrist --board charuco --pattern 7x5 --square-size 0.04 \\
        --marker-size 0.03 --images 'calib/wrist/*.png' --gripper-poses calib/wrist/poses.yaml \\
        --pinhole --output hand_eye.yaml
"""

from __future__ import annotations

import argparse
import glob
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np

from lerobot_omnid.calibration.board import BOARD_KINDS, BoardSpec, board_image
from lerobot_omnid.calibration.hand_eye import (
    HandEyeCalibration,
    load_gripper_poses,
    load_hand_eye_file,
    save_hand_eye_file,
)
from lerobot_omnid.calibration.rig_file import (
    load_calibration_file,
    load_calibration_meta,
    read_mapping_file,
    save_calibration_file,
    write_mapping_file,
)
from lerobot_omnid.calibration.schema import CalibrationError, CameraCalibration
from lerobot_omnid.calibration.solve import (
    CameraResult,
    calibrate_camera,
    load_board_pose,
    world_T_board_from_points,
    world_T_board_on_table,
)
from lerobot_omnid.calibration.solve_hand_eye import HAND_EYE_METHODS, HandEyeResult, calibrate_hand_eye
from lerobot_omnid.keys import image_key


def _expand(patterns: Sequence[str], flag: str = "--intrinsics-images") -> list[Path]:
    paths: list[Path] = []
    for pattern in patterns:
        matches = sorted(glob.glob(pattern)) if glob.has_magic(pattern) else [pattern]
        if not matches:
            raise CalibrationError(f"{flag}: {pattern!r} matches no file")
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

    hand = sub.add_parser(
        "hand-eye",
        help="calibrate a camera on the gripper (eye-in-hand) from a fixed board seen at several robot poses",
    )
    hand.add_argument("--camera", required=True, help="camera name or feature key (observation.images.<cam>)")
    _add_board_args(hand)
    hand.add_argument(
        "--images",
        nargs="+",
        required=True,
        help="images (or quoted globs) of the fixed board, one per robot pose",
    )
    hand.add_argument(
        "--gripper-poses",
        type=Path,
        required=True,
        help="JSON/YAML file: {T_base_gripper: {<image file name>: 4x4 gripper pose in the base frame, m}}",
    )
    hand.add_argument(
        "--method",
        choices=list(HAND_EYE_METHODS),
        default="park",
        help="cv2.calibrateHandEye method (default: %(default)s)",
    )
    known = hand.add_mutually_exclusive_group()
    known.add_argument("--intrinsics-images", nargs="+", help="other images for K (default: --images)")
    known.add_argument(
        "--intrinsics-from",
        type=Path,
        help="reuse this camera's K and distortion from a calibration file or a hand-eye file",
    )
    hand.add_argument(
        "--pinhole",
        action="store_true",
        help="fit K with distortion fixed to zero (best pinhole model of raw, not undistorted images)",
    )
    hand.add_argument(
        "--board-pose-output",
        type=Path,
        help="also write the board's pose in the base frame as a --board-pose file (T_world_board)",
    )
    hand.add_argument("--output", type=Path, required=True, help="hand-eye file to create or update")
    return parser


def _known_intrinsics(path: Path, camera: str) -> CameraCalibration | HandEyeCalibration:
    """The calibration of ``camera`` in a calibration file or a hand-eye file (told apart by the entry's
    ``T_gripper_cam``), for its K, distortion and image size."""
    key = image_key(camera)
    entries = {image_key(str(cam)): entry for cam, entry in read_mapping_file(path).items()}
    if key not in entries:
        raise CalibrationError(f"--intrinsics-from {path}: no camera {key} (has {sorted(entries)})")
    if isinstance(entries[key], Mapping) and "T_gripper_cam" in entries[key]:
        return load_hand_eye_file(path)[key]
    return load_calibration_file(path)[key]


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
        intrinsics = _known_intrinsics(args.intrinsics_from, args.camera)
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


def run_hand_eye(args: argparse.Namespace) -> HandEyeResult:
    result = calibrate_hand_eye(
        args.camera,
        _board(args),
        _expand(args.images, "--images"),
        load_gripper_poses(args.gripper_poses),
        method=args.method,
        intrinsics_images=_expand(args.intrinsics_images or []),
        pinhole=args.pinhole,
        intrinsics=None
        if args.intrinsics_from is None
        else _known_intrinsics(args.intrinsics_from, args.camera),
    )
    save_hand_eye_file(args.output, result.key, result.calibration, result.meta)
    if args.board_pose_output is not None:
        write_mapping_file(args.board_pose_output, {"T_world_board": result.base_T_board})
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
        result = run_camera(args) if args.command == "camera" else run_hand_eye(args)
    except (CalibrationError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(result.summary())
    print(f"wrote {args.output}")
    if args.command == "hand-eye" and args.board_pose_output is not None:
        print(f"wrote {args.board_pose_output}: the board's pose in the base frame, for --board-pose")
    return 0


if __name__ == "__main__":
    sys.exit(main())
