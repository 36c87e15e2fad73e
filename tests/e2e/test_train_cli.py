"""The real `lerobot-train --policy.type=omnid` CLI finds the plugin and writes a loadable checkpoint."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from omnid_testing import TINY_POLICY_FLAGS, make_tiny_dataset

from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

LEROBOT_TRAIN = Path(sys.executable).parent / "lerobot-train"


def test_lerobot_train_cli_trains_omnid_and_checkpoint_loads(tmp_path):
    root = tmp_path / "dataset"
    make_tiny_dataset(root)
    out = tmp_path / "train"
    cmd = [
        str(LEROBOT_TRAIN),
        "--dataset.repo_id=local/tiny",
        f"--dataset.root={root}",
        "--dataset.video_backend=pyav",
        *TINY_POLICY_FLAGS,
        "--policy.cameras=[cam_b,cam_c,cam_d,cam_e]",
        "--steps=3",
        "--batch_size=2",
        "--num_workers=0",
        "--save_freq=3",
        "--log_freq=1",
        f"--output_dir={out}",
        "--wandb.enable=false",
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "step:3" in result.stdout + result.stderr

    checkpoint = out / "checkpoints" / "000003" / "pretrained_model"
    config = json.loads((checkpoint / "config.json").read_text())
    assert config["type"] == "omnid"
    cam_keys = [f"observation.images.cam_{c}" for c in "bcde"]
    assert sorted(config["camera_calibration"]) == cam_keys
    assert config["camera_calibration"]["observation.images.cam_b"]["image_size"] == [64, 64]

    policy = OmniDPolicy.from_pretrained(checkpoint).eval()
    assert policy.camera_keys == cam_keys
    obs = {k: torch.rand(1, 3, 64, 64) for k in cam_keys}
    obs["observation.state"] = torch.randn(1, 10)
    assert policy.select_action(obs).shape == (1, 10)


@pytest.mark.parametrize(
    ("flag", "expected"),
    [
        (
            "--policy.volume_shape=[0,4,2]",
            "`volume_bounds` / `volume_shape`: shape must be three positive cell counts, got (0, 4, 2)",
        ),
        (
            "--policy.calibration_path={missing}",
            "`calibration_path`: calibration file {missing} does not exist",
        ),
        ("--policy.pillar_axis=w", "`pillar_axis`: expected one of ['x', 'y', 'z'], got 'w'"),
    ],
)
def test_lerobot_train_shows_the_config_error(tmp_path, flag, expected):
    """draccus, lerobot-train's parser, reports an OmniDConfig that cannot be built only as "Couldn't
    instantiate class OmniDConfig"; the user reads the config's own message too, before any dataset is
    opened."""
    missing = tmp_path / "missing.json"
    policy_flags = [f for f in TINY_POLICY_FLAGS if not f.startswith("--policy.volume_shape=")]
    cmd = [
        str(LEROBOT_TRAIN),
        "--dataset.repo_id=local/none",
        f"--dataset.root={tmp_path / 'no_dataset'}",
        *policy_flags,
        flag.format(missing=missing),
        f"--output_dir={tmp_path / 'train'}",
        "--wandb.enable=false",
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert result.returncode != 0
    assert expected.format(missing=missing) in result.stderr, result.stderr[-3000:]
    assert not (tmp_path / "train").exists()
