"""LeRobot's stock ACT and VQ-BeT through omnid-benchmark with the real tools at tiny sizes: recorded data,
`lerobot-train` with the benchmark's options for each, `lerobot-eval` and the blind control (black images).
(Their options and reasons: lerobot_omnid/benchmark/methods.py; OmniD and DP: test_omnid_benchmark.py.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from lerobot_omnid.benchmark.plan import TASK0

TINY = "--episodes 1 --steps 2 --batch-size 2 --image-size 64 --num-workers 0 --eval-episodes 1 "
TINY += "--episode-length 10 --settings id --heldout-episodes 0 --methods act,vqbet"


@pytest.mark.slow
def test_act_and_vqbet_train_evaluate_and_run_their_blind_control(tmp_path):
    out = tmp_path / "bench"
    argv = [str(Path(sys.executable).parent / "omnid-benchmark"), "--out", str(out), *TINY.split()]
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=900, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    assert {(c["model"], c["setting"], c["episodes"]) for c in results["cells"]} == {
        ("act", "id", 1),
        ("vqbet", "id", 1),
    }
    assert {(c["model"], c["control"]) for c in results["controls"]} == {("act", "blind"), ("vqbet", "blind")}
    for method in ("act", "vqbet"):
        config = json.loads(
            (
                out / "train" / method / TASK0 / "checkpoints" / "last" / "pretrained_model" / "config.json"
            ).read_text()
        )
        assert config["type"] == method
    # VQ-BeT takes one image: camera B, in training and in evaluation.
    vqbet = json.loads(
        (
            out / "train" / "vqbet" / TASK0 / "checkpoints" / "last" / "pretrained_model" / "config.json"
        ).read_text()
    )
    assert [k for k in vqbet["input_features"] if "images" in k] == ["observation.images.cam_b"]
    stamp = json.loads((out / "stamps" / "eval" / "vqbet" / TASK0 / "id" / "seed1.json").read_text())
    assert "--env.cameras=[cam_b]" in stamp["command"]
