"""Shared helpers of the calibration tests: the benchmark cameras' calibration, a dataset as LeRobot's own
recorder writes it (no calibration), digests of a dataset's files, the calibration boards rendered by the
tests, rigid transforms and the pose error of a recovered camera."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import cv2
import numpy as np
from gym_omnid.calibration import invert_rigid, mujoco_camera_calibration
from gym_omnid.constants import CAMERA_FOVY
from gym_omnid.env import OmniDEnv
from gym_omnid.scene import CAMERA_POSES, look_at_xyaxes
from omnid_testing import ACTION_DIM, STATE_DIM

from lerobot_omnid.calibration.board import BoardSpec
from lerobot_omnid.calibration.solve import world_T_board_on_table

# The dataset of make_uncalibrated_dataset.
REPO_ID = "local/uncalibrated"
CAMS = ("cam_b", "cam_c")
SIZE = (36, 48)  # (height, width) in the dataset: 4:3 like 640x480, not square (swapped sizes are caught)


def sim_calibration(cam: str, size: tuple[int, int] = SIZE) -> dict:
    """JSON-ready calibration of one benchmark camera (the env's placement and field of view)."""
    position, target = CAMERA_POSES[cam]
    xyaxes = look_at_xyaxes(position, target)
    world_R_mjcam = np.stack([xyaxes[:3], xyaxes[3:], np.cross(xyaxes[:3], xyaxes[3:])], axis=1)
    calib = mujoco_camera_calibration(CAMERA_FOVY, np.array(position), world_R_mjcam, size)
    return {"K": calib["K"].tolist(), "T_cam_world": calib["T_cam_world"].tolist(), "image_size": list(size)}


def make_uncalibrated_dataset(root: Path) -> None:
    """A LeRobotDataset as LeRobot's own recorder writes it: video cameras without calibration."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    height, width = SIZE
    features = {
        "observation.state": {"dtype": "float32", "shape": (STATE_DIM,), "names": None},
        "action": {"dtype": "float32", "shape": (ACTION_DIM,), "names": None},
        **{
            f"observation.images.{cam}": {
                "dtype": "video",
                "shape": (height, width, 3),
                "names": ["height", "width", "channels"],
            }
            for cam in CAMS
        },
    }
    dataset = LeRobotDataset.create(REPO_ID, fps=10, features=features, root=root, use_videos=True)
    rng = np.random.default_rng(0)
    for _ in range(4):
        frame = {f"observation.images.{c}": rng.integers(0, 256, (height, width, 3), np.uint8) for c in CAMS}
        frame["observation.state"] = rng.standard_normal(STATE_DIM).astype(np.float32)
        frame["action"] = rng.standard_normal(ACTION_DIM).astype(np.float32)
        frame["task"] = "pick the cube"
        dataset.add_frame(frame)
    dataset.save_episode()
    dataset.finalize()


def digests(root: Path) -> dict[str, str]:
    """SHA-256 of every file below ``root``, by relative path: what a command changed."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


PX_PER_SQUARE = 64  # texture pixels per board square
CHECKERBOARD = BoardSpec("checkerboard", 9, 6, 0.03)  # 30 x 21 cm
CHARUCO = BoardSpec("charuco", 7, 5, 0.06, 0.045, "DICT_4X4_50")  # 42 x 30 cm, readable at 1 m
# The checkerboard the wrist camera sees in the hand-eye tests: on the table, 1 mm above its top.
WORLD_T_BOARD = world_T_board_on_table(0.30, 0.20, 0.0, 0.001)


def board_args(board: BoardSpec) -> list[str]:
    """The board options of ``omnid-calibrate`` for ``board``."""
    args = [
        "--board",
        board.kind,
        "--pattern",
        f"{board.cols}x{board.rows}",
        "--square-size",
        str(board.square_size),
    ]
    if board.kind == "charuco":
        args += ["--marker-size", str(board.marker_size), "--dictionary", board.dictionary]
    return args


def pose_errors(cam_T_world: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(distance between the camera centres in metres, rotation angle between them in degrees)."""
    centre, centre_truth = invert_rigid(cam_T_world)[:3, 3], invert_rigid(truth)[:3, 3]
    delta = cam_T_world[:3, :3] @ truth[:3, :3].T
    angle = math.degrees(math.acos(np.clip((np.trace(delta) - 1) / 2, -1.0, 1.0)))
    return float(np.linalg.norm(centre - centre_truth)), angle


def rigid(rotvec, translation) -> np.ndarray:
    """A 4x4 rigid transform from a rotation vector (radians) and a translation (m)."""
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rotvec, np.float64))[0]
    T[:3, 3] = translation
    return T


def tcp_T(env: OmniDEnv) -> np.ndarray:
    """``T_base_gripper`` (4, 4): the tool centre point's pose in the base frame, now."""
    position, rotation = env.tcp_pose()
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation, position
    return T
