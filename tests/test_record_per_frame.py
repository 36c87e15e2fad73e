"""``omnid-record --per-frame-calibration`` (now the default, the flag still accepted): every camera's
calibration in every frame as dataset columns equal to the env's, a feature schema that is the same for
every rig, so that datasets of two rigs merge with LeRobot's own ``lerobot-edit-dataset``, which refuses
the same datasets recorded with ``--static-calibration``. (The console commands and a training run on the
merge: tests/e2e/test_per_frame_merge_train.py.)"""

from __future__ import annotations

import sys
from pathlib import Path

import gym_omnid.experts
import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.scripts.lerobot_edit_dataset import edit_dataset
from omnid_testing import record_rig

from lerobot_omnid.calibration.frame_columns import (
    EXTRINSICS_NAMES,
    INTRINSICS_NAMES,
    extrinsics_column,
    extrinsics_from_column,
    extrinsics_key,
    intrinsics_column,
    intrinsics_key,
)
from lerobot_omnid.calibration.schema import CALIBRATION_INFO_KEY
from lerobot_omnid.env_config import OmniDEnvConfig
from lerobot_omnid.record import record_dataset

SIZE = 32
CAMERAS = ["cam_b", "cam_wrist"]


def _columns(root: Path, cameras: list[str]) -> pd.DataFrame:
    keys = [key for cam in cameras for key in (extrinsics_key(cam), intrinsics_key(cam))]
    files = sorted((root / "data").rglob("*.parquet"))
    return pd.concat([pd.read_parquet(f, columns=["episode_index", *keys]) for f in files], ignore_index=True)


def _expert_calibrations(seed: int, cameras: list[str], rig: str = "default") -> dict[str, list]:
    """Each camera's (K, T_cam_world) in every frame of one expert attempt, replayed without a dataset."""
    cfg = OmniDEnvConfig(cameras=cameras, image_size=SIZE, rig=rig)
    env = gym.make(cfg.gym_id, disable_env_checker=True, **cfg.gym_kwargs)
    try:
        env.reset(seed=seed)
        expert = gym_omnid.experts.make_expert(env.unwrapped)
        calibs: dict[str, list] = {cam: [] for cam in cameras}
        while True:
            for cam in cameras:
                calibs[cam].append(env.unwrapped.camera_calibration(cam))
            _, _, terminated, truncated, _ = env.step(expert.act())
            if terminated or truncated:
                return calibs
    finally:
        env.close()


def _record(root: Path, rig: str, per_frame_calibration: bool, cameras: list[str] = CAMERAS) -> Path:
    return record_rig(root, rig, per_frame_calibration, cameras, SIZE)


@pytest.fixture(scope="module")
def per_frame_root(tmp_path_factory) -> Path:
    return _record(tmp_path_factory.mktemp("per_frame") / "apple_wrist", "default", True)


def test_columns_are_in_the_schema_and_info_has_no_calibration(per_frame_root):
    meta = LeRobotDatasetMetadata("local/apple_wrist", root=per_frame_root)
    for cam in CAMERAS:
        assert meta.features[extrinsics_key(cam)] == {
            "dtype": "float32",
            "shape": (16,),
            "names": list(EXTRINSICS_NAMES),
        }
        assert meta.features[intrinsics_key(cam)] == {
            "dtype": "float32",
            "shape": (9,),
            "names": list(INTRINSICS_NAMES),
        }
        assert CALIBRATION_INFO_KEY not in meta.features[f"observation.images.{cam}"].get("info", {})
    item = LeRobotDataset("local/apple_wrist", root=per_frame_root, video_backend="pyav")[0]
    assert item[extrinsics_key("cam_wrist")].shape == (16,) and item[intrinsics_key("cam_b")].shape == (9,)


def test_columns_equal_the_env_calibration_in_every_frame(per_frame_root):
    data = _columns(per_frame_root, CAMERAS)
    expected = _expert_calibrations(seed=0, cameras=CAMERAS)
    for cam in CAMERAS:
        assert len(expected[cam]) == len(data)
        extrinsics = np.stack(data[extrinsics_key(cam)])
        intrinsics = np.stack(data[intrinsics_key(cam)])
        assert extrinsics.dtype == intrinsics.dtype == np.float32
        np.testing.assert_array_equal(
            extrinsics, [extrinsics_column(c["T_cam_world"]) for c in expected[cam]]
        )
        np.testing.assert_array_equal(intrinsics, [intrinsics_column(c["K"]) for c in expected[cam]])
    # A fixed camera's columns are constant, the wrist camera's follow the arm.
    assert (np.stack(data[extrinsics_key("cam_b")]) == data[extrinsics_key("cam_b")][0]).all()
    wrist = extrinsics_from_column(np.stack(data[extrinsics_key("cam_wrist")]))
    assert np.ptp(wrist[:, :3, 3], axis=0).max() > 0.1  # metres travelled by the camera's centre


def test_wrist_camera_needs_per_frame_calibration(tmp_path):
    with pytest.raises(ValueError, match=r"cam_wrist moves with the arm.*per_frame_calibration=True"):
        record_dataset(
            tmp_path / "ds", episodes=1, cameras=["cam_wrist"], image_size=SIZE, per_frame_calibration=False
        )
    assert not (tmp_path / "ds").exists()


def _merge(roots: list[Path], out: Path, monkeypatch) -> None:
    """``lerobot-edit-dataset --operation.type merge`` (lerobot/scripts/lerobot_edit_dataset.py): its own
    argument parsing and merge, run in this process to spare the command's start-up."""
    argv = [
        "lerobot-edit-dataset",
        f"--new_repo_id=local/{out.name}",
        f"--new_root={out}",
        "--operation.type=merge",
        f"--operation.repo_ids={[f'local/{root.name}' for root in roots]}",
        f"--operation.roots={[str(root) for root in roots]}",
    ]
    monkeypatch.setattr(sys, "argv", argv)
    edit_dataset()


def test_datasets_of_two_rigs_merge_with_the_columns_and_not_without(tmp_path, monkeypatch):
    cams = ["cam_b"]
    with_columns = [_record(tmp_path / f"{rig}_cols", rig, True, cams) for rig in ("default", "bumped")]
    _merge(with_columns, tmp_path / "merged", monkeypatch)
    merged = _columns(tmp_path / "merged", cams)
    assert sorted(set(merged["episode_index"])) == [0, 1]
    for episode, root in enumerate(with_columns):
        source = np.stack(_columns(root, cams)[extrinsics_key("cam_b")])
        np.testing.assert_array_equal(
            np.stack(merged[merged.episode_index == episode][extrinsics_key("cam_b")]), source
        )
    assert not (
        merged[merged.episode_index == 0][extrinsics_key("cam_b")].iloc[0]
        == merged[merged.episode_index == 1][extrinsics_key("cam_b")].iloc[0]
    ).all()  # the two rigs' calibrations, each in its own episodes
    LeRobotDataset("local/merged", root=tmp_path / "merged", video_backend="pyav")[0]

    static = [_record(tmp_path / f"{rig}_static", rig, False, cams) for rig in ("default", "bumped")]
    with pytest.raises(ValueError, match="Same features is expected"):
        _merge(static, tmp_path / "merged_static", monkeypatch)
