"""Fine-tuning on a new camera with replayed episodes, as the new-camera protocol's replay hypothesis runs
it with the real tools at tiny sizes: a B-E OmniD, two recordings with cameras A-E (camera A shown alone,
then hidden: ``omnid-record --hidden-cameras``), LeRobot's merge, ``lerobot-train --policy.path`` on all five
cameras, ``lerobot-eval`` with camera A alone. (The column: tests/test_record_hidden_cameras.py; the
policy's mask: tests/policy/test_camera_visible.py; the plan: tests/benchmark/test_new_camera.py.)"""

from __future__ import annotations

import json
import os
import subprocess

import pytest
from gym_omnid import CAMERAS
from omnid_testing import TINY_POLICY_FLAGS

from lerobot_omnid.benchmark import commands
from lerobot_omnid.camera_visibility import CAMERA_VISIBLE_KEY
from lerobot_omnid.measure.engine import CHECKPOINT

SIZE = 32
BCDE = ("cam_b", "cam_c", "cam_d", "cam_e")


def run(cmd: list[str]) -> None:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=env)
    assert proc.returncode == 0, " ".join(cmd)[:300] + "\n" + proc.stdout[-2000:] + proc.stderr[-3000:]


@pytest.mark.slow
def test_replayed_and_new_camera_episodes_fine_tune_one_omnid(tmp_path):
    data = tmp_path / "data"
    run(commands.record_command("select_apple", 1, BCDE, SIZE, data / "bcde"))
    tiny = [*TINY_POLICY_FLAGS, f"--policy.cameras={commands.json_list(BCDE)}"]
    run(commands.train_command(data / "bcde", tmp_path / "pretrained", tiny, 2, 2, num_workers=0))
    parts = []
    for name, seed, hidden in (("a", 100_000, BCDE), ("replay", 0, ("cam_a",))):
        root = data / name
        cmd = commands.record_command("select_apple", 1, CAMERAS, SIZE, root, seed=seed)
        run([*cmd, "--hidden-cameras", ",".join(hidden)])
        parts.append(root)
    run(commands.merge_command(parts, data / "merged"))
    flags = [f"--policy.path={tmp_path / 'pretrained' / CHECKPOINT}", "--policy.device=cpu"]
    flags += ["--policy.push_to_hub=false", f"--policy.cameras={commands.json_list(CAMERAS)}"]
    run(commands.train_command(data / "merged", tmp_path / "tuned", flags, 2, 2, num_workers=0))
    config = json.loads((tmp_path / "tuned" / CHECKPOINT / "config.json").read_text())
    assert config["camera_visible_names"] == list(CAMERAS)
    assert CAMERA_VISIBLE_KEY not in config["input_features"]
    assert len([k for k in config["input_features"] if ".images." in k]) == 5
    extra = ["--env.episode_length=5", "--env.per_frame_calibration=true", '--policy.cameras=["cam_a"]']
    extra.append('--policy.frame_calibration=["observation.images.cam_a"]')
    evaluate = commands.eval_command(
        tmp_path / "tuned" / CHECKPOINT,
        tmp_path / "eval",
        "select_apple",
        "id",
        ("cam_a",),
        SIZE,
        1,
        "cpu",
        seed=70_000,
        extra=extra,
    )
    run(evaluate)
    assert json.loads((tmp_path / "eval" / "eval_info.json").read_text())["overall"]["n_episodes"] == 1
