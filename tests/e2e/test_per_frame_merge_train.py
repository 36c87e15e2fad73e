"""``omnid-record --per-frame-calibration`` as a user types it: two rigs recorded by the console command,
merged with LeRobot's own ``lerobot-edit-dataset``, and one OmniD trained on both by ``lerobot-train``,
reading every frame's calibration from the columns. (The columns themselves:
tests/test_record_per_frame.py.)"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from omnid_testing import TINY_POLICY_FLAGS

from lerobot_omnid.calibration.frame_columns import extrinsics_key
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

SIZE = 32


@pytest.fixture
def record_two_rigs_merge_train(tmp_path) -> dict:
    """The console commands of the test below; lerobot-train once the merge succeeded."""
    bin_dir = Path(sys.executable).parent
    roots = [tmp_path / rig for rig in ("closer", "higher")]
    for root in roots:
        record = [str(bin_dir / "omnid-record"), "--episodes", "1", "--cameras", "cam_c,cam_wrist"]
        record += ["--image-size", str(SIZE), "--rig", root.name, "--per-frame-calibration"]
        record += ["--root", str(root), "--repo-id", f"local/{root.name}"]
        subprocess.run(record, capture_output=True, check=True, timeout=600)
    merge = [
        str(bin_dir / "lerobot-edit-dataset"),
        "--new_repo_id=local/merged",
        f"--new_root={tmp_path / 'm'}",
    ]
    merge += ["--operation.type=merge", f"--operation.repo_ids={[f'local/{r.name}' for r in roots]}"]
    merge += [f"--operation.roots={[str(r) for r in roots]}"]
    ran = {"merge": subprocess.run(merge, capture_output=True, text=True, timeout=600)}
    if ran["merge"].returncode == 0:
        train = [
            str(bin_dir / "lerobot-train"),
            "--dataset.repo_id=local/merged",
            f"--dataset.root={tmp_path / 'm'}",
        ]
        train += ["--dataset.video_backend=pyav", *TINY_POLICY_FLAGS, "--steps=2", "--batch_size=2"]
        train += ["--num_workers=0", "--save_freq=2", f"--output_dir={tmp_path / 'train'}"]
        train += ["--wandb.enable=false"]
        ran["train"] = subprocess.run(train, capture_output=True, text=True, timeout=600)
    return {"tmp_path": tmp_path, **ran}


@pytest.mark.slow
def test_console_commands_record_two_rigs_and_merge(record_two_rigs_merge_train):
    """The merge of tests/test_record_per_frame.py with the console commands a user types: ``omnid-record
    --rig ... --per-frame-calibration`` twice, then ``lerobot-edit-dataset --operation.type merge``."""
    ran = record_two_rigs_merge_train
    tmp_path = ran["tmp_path"]
    proc = ran["merge"]
    assert proc.returncode == 0, proc.stderr[-3000:]
    merged = LeRobotDataset("local/merged", root=tmp_path / "m", video_backend="pyav")
    assert merged.num_episodes == 2
    first, last = merged[0], merged[len(merged) - 1]
    assert not np.array_equal(first[extrinsics_key("cam_c")], last[extrinsics_key("cam_c")])

    # One OmniD model learns from both rigs: lerobot-train reads every frame's calibration from the columns.
    out = tmp_path / "train"
    proc = ran["train"]
    assert proc.returncode == 0, proc.stderr[-3000:]
    checkpoint = out / "checkpoints" / "last" / "pretrained_model"
    config = json.loads((checkpoint / "config.json").read_text())
    keys = ["observation.images.cam_c", "observation.images.cam_wrist"]
    assert config["frame_calibration"] == keys and config["camera_calibration"] == {}
    assert sorted(config["input_features"]) == [*keys, "observation.state"]  # the columns are not state
    policy = OmniDPolicy.from_pretrained(checkpoint).eval()
    obs = {k: v[None] for k, v in last.items() if k.startswith("observation.") and k != "observation.state"}
    obs["observation.state"] = last["observation.state"][None]
    assert policy.select_action(obs).shape == (1, last["action"].shape[0])
