"""Datasets of two rigs recorded by ``omnid-record`` with the default flags merge with LeRobot's own
``lerobot-edit-dataset`` (the console command, offline) and keep each episode's own rig's calibration.
(The default form itself: tests/test_default_calibration.py.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from omnid_testing import record_rigs_with_default_flags

from lerobot_omnid.calibration.frame_columns import (
    extrinsics_column,
    extrinsics_key,
    intrinsics_column,
    intrinsics_key,
)
from lerobot_omnid.calibration.schema import CALIBRATION_INFO_KEY
from lerobot_omnid.env_config import OmniDEnvConfig

SIZE = 32
CAMERA = "cam_b"
IMAGE_KEY = f"observation.images.{CAMERA}"
RIGS = ("default", "closer")
BIN = Path(sys.executable).parent


def _rig_calibration(rig: str) -> dict:
    """``cam_b``'s calibration in ``rig`` at ``SIZE``, as the env reports it."""
    return OmniDEnvConfig(cameras=[CAMERA], image_size=SIZE, rig=rig).camera_calibrations()[IMAGE_KEY]


@pytest.fixture(scope="module")
def rig_roots(tmp_path_factory) -> dict[str, Path]:
    """One expert episode per rig, recorded by ``omnid-record`` with no calibration flag."""
    return record_rigs_with_default_flags(tmp_path_factory.mktemp("default_calibration"), RIGS, CAMERA, SIZE)


def test_default_recordings_of_two_rigs_merge_and_keep_each_rigs_calibration(rig_roots, tmp_path):
    """``lerobot-edit-dataset --operation.type merge`` (the console command, offline) on two datasets
    recorded with the default flags; every frame of the merged dataset carries its own rig's calibration."""
    merged = tmp_path / "merged"
    cmd = [
        str(BIN / "lerobot-edit-dataset"),
        "--new_repo_id=local/merged",
        f"--new_root={merged}",
        "--operation.type=merge",
        f"--operation.repo_ids={json.dumps([f'local/{rig}' for rig in RIGS])}",
        f"--operation.roots={json.dumps([str(rig_roots[rig]) for rig in RIGS])}",
    ]
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]

    dataset = LeRobotDataset("local/merged", root=merged, video_backend="pyav")
    assert dataset.num_episodes == len(RIGS)
    assert CALIBRATION_INFO_KEY not in dataset.meta.features[IMAGE_KEY]["info"]
    frames = dataset.hf_dataset.with_format("numpy")
    episodes = np.asarray(frames["episode_index"])
    extrinsics = np.stack(frames[extrinsics_key(CAMERA)])
    intrinsics = np.stack(frames[intrinsics_key(CAMERA)])
    for episode, rig in enumerate(RIGS):  # merged in the order of --operation.roots
        calib = _rig_calibration(rig)
        rows = np.flatnonzero(episodes == episode)
        assert len(rows) == LeRobotDatasetMetadata(f"local/{rig}", root=rig_roots[rig]).total_frames
        expected_T, expected_K = extrinsics_column(calib["T_cam_world"]), intrinsics_column(calib["K"])
        np.testing.assert_array_equal(extrinsics[rows], np.broadcast_to(expected_T, (len(rows), 16)))
        np.testing.assert_array_equal(intrinsics[rows], np.broadcast_to(expected_K, (len(rows), 9)))
        for row in rows[[0, -1]]:  # as a policy's data loader reads them
            item = dataset[int(row)]
            assert int(item["episode_index"]) == episode
            np.testing.assert_array_equal(item[extrinsics_key(CAMERA)].numpy(), expected_T)
            np.testing.assert_array_equal(item[intrinsics_key(CAMERA)].numpy(), expected_K)
    first, second = (extrinsics_column(_rig_calibration(rig)["T_cam_world"]) for rig in RIGS)
    assert not np.allclose(first, second, atol=1e-2)  # two rigs, two calibrations
