"""``omnid-record --suite metaworld`` as a console command: one MetaWorld episode with the four default
cameras and the hand camera's per-frame calibration; and the package without metaworld installed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from gym_omnid.metaworld_suite import DEFAULT_CAMERAS, FIXED_CAMERAS, HAND_CAMERA, STATE_NAMES
from omnid_testing import assert_only_dataset_dirs, load_recording

from lerobot_omnid.calibration.frame_columns import extrinsics_key, intrinsics_key

SIZE = 32
BIN = Path(sys.executable).parent
TASK = "push-v3"
REPO_ID = f"local/omnid_metaworld_{TASK}"  # omnid-record's default for --suite metaworld --task push-v3


def test_records_one_metaworld_episode(tmp_path) -> None:
    pytest.importorskip("metaworld")
    root = tmp_path / "ds"
    argv = ["--suite", "metaworld", "--task", TASK, "--episodes", "1", "--image-size", str(SIZE)]
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(
        [str(BIN / "omnid-record"), *argv, "--root", str(root)],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    assert "saved 1/1 episodes" in proc.stdout
    assert_only_dataset_dirs(root)
    ds = load_recording(root, REPO_ID)
    meta = ds.meta
    assert ds.num_episodes == 1 and meta.fps == 80 and meta.robot_type == "metaworld_sawyer"
    assert meta.video_keys == [f"observation.images.{cam}" for cam in DEFAULT_CAMERAS]
    assert meta.features["observation.state"]["names"] == list(STATE_NAMES)
    assert meta.features["action"]["shape"] == (4,)
    frames = [ds[i] for i in (0, len(ds) - 1)]
    assert frames[0]["task"] == "push"
    for frame in frames:
        for cam in DEFAULT_CAMERAS:
            assert frame[f"observation.images.{cam}"].shape == (3, SIZE, SIZE)
            assert frame[extrinsics_key(cam)].shape == (16,) and frame[intrinsics_key(cam)].shape == (9,)
    # The hand camera's calibration changes with the hand; the fixed cameras' does not.
    hand = [f[extrinsics_key(HAND_CAMERA)].numpy() for f in frames]
    assert np.abs(hand[0] - hand[1]).max() > 1e-3
    for cam in FIXED_CAMERAS:
        np.testing.assert_array_equal(frames[0][extrinsics_key(cam)], frames[1][extrinsics_key(cam)])


# Run with metaworld hidden (an import of it fails, as where it is not installed).
WITHOUT_METAWORLD = """
import sys
sys.modules["metaworld"] = None
import lerobot_omnid
from lerobot_omnid.env_config_metaworld import OmniDMetaWorldEnvConfig
from lerobot_omnid.record import main
cfg = OmniDMetaWorldEnvConfig(task="push-v3")
import gymnasium as gym
try:
    gym.make(cfg.gym_id, **cfg.gym_kwargs)
except ImportError as e:
    print("ImportError:", e)
"""


def test_the_default_install_works_without_metaworld() -> None:
    """Importing the package, registering and configuring the suite need no metaworld; making an env
    says which extra to install."""
    proc = subprocess.run(
        [sys.executable, "-c", WITHOUT_METAWORLD], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "ImportError: the MetaWorld suite needs the optional dependency metaworld" in proc.stdout
    assert "lerobot_policy_omnid[metaworld]" in proc.stdout
