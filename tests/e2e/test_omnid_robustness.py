"""``omnid-robustness`` with the real tools at tiny size: a tiny OmniD recorded by ``omnid-record``, trained
by ``lerobot-train`` and evaluated by ``lerobot-eval`` under each perturbation; then resumed. (The plan,
the files and the report: tests/benchmark/test_robustness.py.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from gym_omnid import TRAIN_CAMERAS
from omnid_testing import TINY_POLICY_FLAGS


@pytest.fixture
def record_train_robustness(tmp_path) -> dict:
    """omnid-record, lerobot-train, omnid-robustness (the first run; the test reruns it)."""
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    bin_dir = Path(sys.executable).parent
    data, train = tmp_path / "data", tmp_path / "train"
    record = [
        str(bin_dir / "omnid-record"),
        "--task",
        "select_apple",
        "--episodes",
        "1",
        "--image-size",
        "32",
    ]
    record += ["--cameras", ",".join(TRAIN_CAMERAS), "--root", str(data), "--repo-id", "local/data"]
    record += ["--static-calibration"]  # omnid-robustness perturbs a checkpoint's static calibration
    subprocess.run(record, capture_output=True, text=True, check=True, timeout=300, env=env)
    cmd = [str(bin_dir / "lerobot-train"), "--dataset.repo_id=local/data", f"--dataset.root={data}"]
    cmd += [
        "--dataset.video_backend=pyav",
        *TINY_POLICY_FLAGS,
        "--steps=2",
        "--batch_size=2",
        "--num_workers=0",
    ]
    cmd += ["--save_freq=2", f"--output_dir={train}", "--wandb.enable=false"]
    ran = {"train": subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)}
    checkpoint = train / "checkpoints" / "last" / "pretrained_model"
    out = tmp_path / "robustness"
    argv = [str(bin_dir / "omnid-robustness"), "--checkpoint", f"tiny={checkpoint}", "--out", str(out)]
    argv += ["--conditions", "calibration,bumped,dead", "--levels", "0,1", "--draws", "1"]
    argv += ["--dead-cameras", "cam_b", "--eval-episodes", "1", "--episode-length", "6"]
    if ran["train"].returncode == 0:
        ran["robustness"] = subprocess.run(argv, capture_output=True, text=True, timeout=900, env=env)
    return {"out": out, "argv": argv, "env": env, **ran}


@pytest.mark.slow
def test_real_tools_end_to_end_tiny(record_train_robustness):
    """A tiny OmniD trained by the real lerobot-train, evaluated by the real lerobot-eval under a calibration
    error, a bumped camera and a dead camera (removed, black, black from mid-episode); then resumed."""
    ran = record_train_robustness
    out, argv, env = ran["out"], ran["argv"], ran["env"]
    proc = ran["train"]
    assert proc.returncode == 0, proc.stderr[-3000:]
    proc = ran["robustness"]
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "6 evaluations: 6 ran" in proc.stdout
    rows = json.loads((out / "summary.json").read_text())["results"]["checkpoints"]["tiny"]["rows"]
    assert [r["condition"] for r in rows] == [
        "nominal",
        "calibration",
        "bumped",
        "dead_removed",
        "dead_black",
        "dead_black_mid",
    ]
    assert all(r["episodes"] == 1 for r in rows)
    assert (out / "robustness_tiny.png").is_file() and "## tiny" in (out / "report.md").read_text()
    # What lerobot-eval rendered: a calibration error leaves the scene as it was, a bumped camera moves it.
    nominal, calibration, bumped = (
        _first_frame(out / "eval" / "tiny" / cell / "seed1")
        for cell in ("nominal", "calibration/1cm_1deg/draw1", "bumped/1cm_1deg/draw1")
    )
    np.testing.assert_array_equal(calibration, nominal)
    assert np.abs(bumped.astype(int) - nominal).mean() > 1.0
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0 and "6 evaluations: 6 reused, 0 ran" in proc.stdout


def _first_frame(eval_dir: Path) -> np.ndarray:
    """The first frame of the episode video lerobot-eval wrote into ``eval_dir``."""
    import av

    (video,) = eval_dir.rglob("*.mp4")
    with av.open(str(video)) as container:
        return next(container.decode(video=0)).to_ndarray(format="rgb24")
