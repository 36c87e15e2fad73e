"""Hand-eye calibration of a camera on the gripper and the per-frame extrinsics it gives,
``T_cam_world(t) = inv(T_base_gripper(t) @ T_gripper_cam)``: the pure functions (a camera fixed on a moving
gripper, exact views, the env's wrist camera along a move), the hand-eye and gripper-pose files, and the
documented snippet for a real arm's dataset. (``omnid-calibrate hand-eye`` on rendered images:
test_hand_eye_renders.py.)
"""

from __future__ import annotations

import math
import re
import shlex
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from calibration_testing import CHECKERBOARD, WORLD_T_BOARD, rigid, tcp_T
from gym_omnid.calibration import intrinsics_from_fovy
from gym_omnid.constants import WRIST_CAMERA, WRIST_CAMERA_FOVY
from gym_omnid.env import OmniDEnv

from lerobot_omnid.calibration.board import BoardDetection
from lerobot_omnid.calibration.calibrate import build_parser
from lerobot_omnid.calibration.frame_columns import extrinsics_key, intrinsics_key
from lerobot_omnid.calibration.hand_eye import (
    HandEyeCalibration,
    calibration_columns,
    cam_T_world_from_gripper,
    invert_rigid,
    load_gripper_poses,
    load_hand_eye_file,
    save_hand_eye_file,
)
from lerobot_omnid.calibration.rig_file import load_calibration_meta, read_mapping_file
from lerobot_omnid.calibration.schema import CalibrationError
from lerobot_omnid.calibration.solve_hand_eye import board_consistency, solve_gripper_T_cam

HEIGHT, WIDTH = 480, 640


def random_rigid(rng: np.random.Generator, n: int, reach_m: float = 0.5) -> np.ndarray:
    return np.stack([rigid(rng.normal(size=3), rng.uniform(-reach_m, reach_m, 3)) for _ in range(n)])


# --- the pure functions ---------------------------------------------------------------------------


def test_invert_rigid_round_trip():
    rng = np.random.default_rng(0)
    a_T_b = random_rigid(rng, 6).reshape(2, 3, 4, 4)
    b_T_a = invert_rigid(a_T_b)
    np.testing.assert_allclose(a_T_b @ b_T_a, np.broadcast_to(np.eye(4), a_T_b.shape), atol=1e-12)
    np.testing.assert_allclose(invert_rigid(b_T_a), a_T_b, atol=1e-12)


def test_per_frame_extrinsics_project_like_the_camera_on_the_gripper():
    """Points seen by a camera fixed on a moving gripper: ``K @ T_cam_world(t) @ X`` equals the projection
    computed the long way, through the gripper frame, by solving for the coordinates in each frame."""
    rng = np.random.default_rng(1)
    gripper_T_cam = rigid([0.1, -0.2, 3.0], [0.0, 0.08, 0.02])
    base_T_gripper = random_rigid(rng, 5)
    K = np.array([[400.0, 0.0, 320.0], [0.0, 410.0, 240.0], [0.0, 0.0, 1.0]])
    cam_T_world = cam_T_world_from_gripper(base_T_gripper, gripper_T_cam)
    assert cam_T_world.shape == (5, 4, 4)
    xyz_world = np.concatenate([rng.uniform(-1, 1, (7, 3)), np.ones((7, 1))], axis=1)
    for t in range(5):
        xyz_gripper = np.linalg.solve(base_T_gripper[t], xyz_world.T)
        xyz_cam = np.linalg.solve(gripper_T_cam, xyz_gripper)
        uvw = K @ xyz_cam[:3]
        uvw_fast = K @ (cam_T_world[t] @ xyz_world.T)[:3]
        np.testing.assert_allclose(uvw_fast[:2] / uvw_fast[2], uvw[:2] / uvw[2], atol=1e-9)
    with pytest.raises(ValueError, match="expected base_T_gripper"):
        cam_T_world_from_gripper(np.eye(3), gripper_T_cam)


def test_exact_views_give_the_exact_hand_eye_and_zero_residuals():
    """Board poses made from a known ``gripper_T_cam``: ``cv2.calibrateHandEye`` returns it, and every view
    implies the same board pose (zero spread, zero reprojection error)."""
    rng = np.random.default_rng(2)
    gripper_T_cam = rigid([0.05, 0.1, 2.9], [0.01, 0.08, -0.03])
    base_T_board = WORLD_T_BOARD
    K = np.array([[450.0, 0.0, 319.5], [0.0, 450.0, 239.5], [0.0, 0.0, 1.0]])
    base_T_gripper = np.stack([rigid(rng.uniform(-0.5, 0.5, 3), rng.uniform(-0.3, 0.3, 3)) for _ in range(8)])
    cam_T_board = invert_rigid(base_T_gripper @ gripper_T_cam) @ base_T_board
    xyz_board = CHECKERBOARD.object_points()
    views = []
    for T in cam_T_board:
        uv, _ = cv2.projectPoints(xyz_board, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K, np.zeros(0))
        views.append(BoardDetection(uv.reshape(-1, 2), xyz_board, (HEIGHT, WIDTH)))
    for method in ("park", "tsai", "daniilidis"):
        solved = solve_gripper_T_cam(base_T_gripper, cam_T_board, method)
        np.testing.assert_allclose(solved, gripper_T_cam, atol=1e-6, err_msg=method)
    mean, residuals = board_consistency(
        base_T_gripper, gripper_T_cam, cam_T_board, views, CHECKERBOARD, K, np.zeros(0)
    )
    np.testing.assert_allclose(mean, base_T_board, atol=1e-9)
    assert max(residuals.values()) < 1e-3, residuals  # mm, degrees, px


def test_columns_follow_the_moving_wrist_camera():
    """The columns built from the gripper's poses equal the env's own per-step calibration of ``cam_wrist``
    while the arm moves, with K given at 10x the dataset's resolution (rescaled)."""
    env = OmniDEnv(
        "select_apple",
        cameras=(WRIST_CAMERA,),
        image_size=(48, 64),
        per_frame_calibration=True,
        render_mode=None,
    )
    try:
        obs, _ = env.reset(seed=0)
        first = env.camera_calibration(WRIST_CAMERA)
        tcp_T_cam = invert_rigid(tcp_T(env)) @ invert_rigid(first["T_cam_world"])
        K_full = intrinsics_from_fovy(WRIST_CAMERA_FOVY, 480, 640)
        hand_eye = HandEyeCalibration(tuple(map(tuple, K_full)), tuple(map(tuple, tcp_T_cam)), (480, 640))
        position, rotation = env.tcp_pose()
        poses, expected = [tcp_T(env)], [obs]
        for offset in ([0.05, 0.0, 0.0], [0.05, 0.08, -0.05], [-0.03, -0.06, 0.04]):
            action = np.concatenate([position + offset, rotation[:, 0], rotation[:, 1], [0.0]])
            obs, *_ = env.step(action.astype(np.float32))
            poses.append(tcp_T(env))
            expected.append(obs)
    finally:
        env.close()
    assert np.abs(np.diff(np.stack(poses)[:, :3, 3], axis=0)).max() > 0.01  # the arm did move
    columns = calibration_columns("observation.images.cam_wrist", np.stack(poses), hand_eye, (48, 64))
    extrinsics, intrinsics = columns[extrinsics_key(WRIST_CAMERA)], columns[intrinsics_key(WRIST_CAMERA)]
    assert extrinsics.shape == (4, 16) and intrinsics.shape == (4, 9) and extrinsics.dtype == np.float32
    for t, obs in enumerate(expected):
        np.testing.assert_allclose(extrinsics[t], obs[f"extrinsics.{WRIST_CAMERA}"], atol=1e-5)
        np.testing.assert_allclose(intrinsics[t], obs[f"intrinsics.{WRIST_CAMERA}"], atol=1e-4)
    distorted = HandEyeCalibration(hand_eye.K, hand_eye.T_gripper_cam, (480, 640), (0.1, 0.0, 0.0, 0.0))
    with pytest.raises(CalibrationError, match=r"cam_wrist\.distortion: non-zero"):
        calibration_columns("cam_wrist", np.stack(poses), distorted)
    with pytest.raises(CalibrationError, match=r"cam_wrist\.image_size: .* another aspect ratio"):
        calibration_columns("cam_wrist", np.stack(poses), hand_eye, (48, 48))


# --- files ------------------------------------------------------------------------------------------


def test_hand_eye_file_round_trip_and_named_errors(tmp_path):
    K = ((450.0, 0.0, 319.5), (0.0, 450.0, 239.5), (0.0, 0.0, 1.0))
    T = tuple(map(tuple, rigid([0.0, 0.0, math.pi], [0.0, 0.08, 0.0]).tolist()))
    calib = HandEyeCalibration(K, T, (480, 640), (0.01, -0.02, 0.0, 0.0, 0.0))
    path = tmp_path / "hand_eye.yaml"
    save_hand_eye_file(path, "wrist", calib, {"method": "park", "T_base_board": np.eye(4)})
    save_hand_eye_file(path, "left_wrist", calib)
    loaded = load_hand_eye_file(path)
    assert sorted(loaded) == ["observation.images.left_wrist", "observation.images.wrist"]
    assert loaded["observation.images.wrist"] == calib
    assert load_calibration_meta(path)["observation.images.wrist"]["method"] == "park"
    data = read_mapping_file(path)
    data["observation.images.wrist"]["T_cam_world"] = data["observation.images.wrist"]["T_gripper_cam"]
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CalibrationError, match=r"hand_eye\.yaml: observation\.images\.wrist: unknown field"):
        load_hand_eye_file(path)
    del data["observation.images.wrist"]["T_cam_world"]
    data["observation.images.wrist"]["T_gripper_cam"][0][0] = 2.0
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CalibrationError, match=r"wrist\.T_gripper_cam: rotation part is not orthonormal"):
        load_hand_eye_file(path)


def test_gripper_poses_file_errors_are_named(tmp_path):
    path = tmp_path / "poses.yaml"
    pose = rigid([0.0, 0.3, 0.0], [0.3, 0.0, 0.4])
    path.write_text(yaml.safe_dump({"T_base_gripper": {"a.png": np.round(pose, 4).tolist()}}))
    np.testing.assert_allclose(load_gripper_poses(path)["a.png"], pose, atol=1e-3)
    millimetres, scaled = pose.copy(), pose.copy()
    millimetres[:3, 3] *= 1000
    scaled[:3, :3] *= 1.1
    for data, message in (
        (
            {"T_base_gripper": {"a.png": pose.tolist()}, "units": "m"},
            r"expected only 'T_base_gripper'.*units",
        ),
        ({"T_base_gripper": {"a.png": millimetres.tolist()}}, r"a\.png: the gripper is .* must be in metres"),
        ({"T_base_gripper": {"b.png": scaled.tolist()}}, r"T_base_gripper\.b\.png: the rotation part is not"),
        ({"T_base_gripper": {"c.png": pose[:3].tolist()}}, r"c\.png: expected a finite 4x4 matrix"),
    ):
        path.write_text(yaml.safe_dump(data))
        with pytest.raises(CalibrationError, match=message):
            load_gripper_poses(path)


SO101_JOINTS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")


class StandInKinematics:
    """``lerobot.model.kinematics.RobotKinematics`` without placo or a URDF: a made-up arm, joint positions in
    degrees -> ``T_base_gripper``."""

    def __init__(self, urdf_path: str, target_frame_name: str, joint_names: list[str]) -> None:
        assert target_frame_name == "gripper_frame_link" and list(joint_names) == list(SO101_JOINTS[:5])

    def forward_kinematics(self, joint_pos_deg: np.ndarray) -> np.ndarray:
        q = np.radians(np.asarray(joint_pos_deg, np.float64))
        return rigid([q[1], q[2], q[0]], [0.2 + 0.1 * q[3], 0.1 * q[4], 0.3])


def make_so101_dataset(root: Path, frames: int) -> np.ndarray:
    """A LeRobot dataset as an SO-101 records it (six joint positions, a wrist video); its states."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    features = {
        "observation.state": {"dtype": "float32", "shape": (6,), "names": [f"{j}.pos" for j in SO101_JOINTS]},
        "action": {"dtype": "float32", "shape": (6,), "names": [f"{j}.pos" for j in SO101_JOINTS]},
        "observation.images.wrist": {
            "dtype": "video",
            "shape": (36, 48, 3),
            "names": ["height", "width", "channels"],
        },
    }
    dataset = LeRobotDataset.create("me/pick_cube", fps=10, features=features, root=root, use_videos=True)
    rng = np.random.default_rng(3)
    states = rng.uniform(-90, 90, (frames, 6)).astype(np.float32)
    for episode in np.array_split(states, 2):
        for state in episode:
            frame = {"observation.state": state, "action": state, "task": "pick up the cube"}
            frame["observation.images.wrist"] = rng.integers(0, 256, (36, 48, 3), np.uint8)
            dataset.add_frame(frame)
        dataset.save_episode()
    dataset.finalize()
    return states


def test_docs_hand_eye_section_runs(tmp_path, monkeypatch):
    """docs/calibration.md's wrist camera section: its commands parse, its Python compiles, and the dataset
    snippet, run on a small SO-101-like dataset with a stand-in for the kinematics, writes the columns of
    ``inv(T_base_gripper(t) @ T_gripper_cam)`` for every frame, with K rescaled to the dataset's images."""
    import lerobot.model.kinematics
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    doc = (Path(__file__).parents[2] / "docs" / "calibration.md").read_text()
    section = doc.split("## A camera on the gripper")[1].split("\n## ")[0]
    blocks = re.findall(r"```(bash|python)\n(.*?)```", section, flags=re.S)
    commands, snippets = 0, []
    for language, block in blocks:
        if language == "python":
            snippets.append(compile(block, "docs/calibration.md", "exec"))
            continue
        for command in block.replace("\\\n", " ").splitlines():
            words = shlex.split(command)
            if words and words[0] == "omnid-calibrate":
                build_parser().parse_args(words[1:])
                commands += 1
    assert commands >= 1 and len(snippets) == 2

    states = make_so101_dataset(tmp_path / "data" / "pick_cube", frames=6)
    K = ((416.0, 0.0, 319.5), (0.0, 416.0, 239.5), (0.0, 0.0, 1.0))
    gripper_T_cam = rigid([0.0, 0.0, 0.3], [0.0, -0.08, -0.14])
    save_hand_eye_file(
        tmp_path / "hand_eye.yaml",
        "wrist",
        HandEyeCalibration(K, tuple(map(tuple, gripper_T_cam)), (480, 640)),
    )
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(lerobot.model.kinematics, "RobotKinematics", StandInKinematics)
    exec(snippets[1], {})

    written = LeRobotDataset(
        "me/pick_cube_wrist", root=tmp_path / "data" / "pick_cube_wrist", video_backend="pyav"
    )
    fk = StandInKinematics("", "gripper_frame_link", list(SO101_JOINTS[:5]))
    scale = 48 / 640  # = 36 / 480; pixel centres at integers: u' = (u + 0.5) * scale - 0.5
    f, cx, cy = 416.0 * scale, 320.0 * scale - 0.5, 240.0 * scale - 0.5
    K_small = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    for t, state in enumerate(states):
        frame = written[t]
        expected = invert_rigid(fk.forward_kinematics(state[:5]) @ gripper_T_cam)
        np.testing.assert_allclose(frame[extrinsics_key("wrist")].numpy().reshape(4, 4), expected, atol=1e-5)
        np.testing.assert_allclose(frame[intrinsics_key("wrist")].numpy().reshape(3, 3), K_small, atol=1e-4)
