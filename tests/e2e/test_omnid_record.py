"""``omnid-record`` as a console command, and its recording in the stock LeRobot CLIs: Ctrl-C leaves a
loadable dataset; a stock Diffusion Policy trains on a recording with ``lerobot-train`` and evaluates in
the env with ``lerobot-eval``."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from gym_omnid.constants import CAMERAS, STATE_NAMES
from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
from omnid_testing import assert_only_dataset_dirs, load_recording, record_five_cameras
from safetensors.torch import load_file

from lerobot_omnid.calibration.frame_columns import extrinsics_key
from lerobot_omnid.record import EXIT_INTERRUPTED

# The diffusion checkpoint (two steps of lerobot-train) serves both of its tests: one worker.
pytestmark = pytest.mark.xdist_group("omnid_record")

SIZE = 64
REPO_ID = "local/omnid_select_apple"  # omnid-record's default for select_apple
BIN = Path(sys.executable).parent


@pytest.fixture(scope="module")
def five_cam_root(tmp_path_factory) -> Path:
    return record_five_cameras(tmp_path_factory.mktemp("record") / "five_cams", SIZE)


def test_console_script_sigint_leaves_loadable_dataset(tmp_path):
    root = tmp_path / "ds"
    proc = subprocess.Popen(
        [
            str(BIN / "omnid-record"),
            "--episodes",
            "50",
            "--cameras",
            "cam_b",
            "--image-size",
            str(SIZE),
            "--root",
            str(root),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    first_video = root / "videos" / "observation.images.cam_b" / "chunk-000" / "file-000.mp4"
    deadline = time.monotonic() + 120
    while not first_video.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == EXIT_INTERRUPTED, err
    assert "Interrupted: saved" in out
    assert "Traceback" not in err
    ds = load_recording(root)
    assert 1 <= ds.num_episodes < 50
    assert ds[len(ds) - 1]["observation.images.cam_b"].shape == (3, SIZE, SIZE)
    assert_only_dataset_dirs(root)


# Without FFmpeg's shared libraries, torchcodec's import fails and LeRobot logs the loading tracebacks
# between these markers before falling back to PyAV; any other traceback is a real error.
TORCHCODEC_LOADING_TRACEBACK = re.compile(
    r"\[start of libtorchcodec loading traceback\].*?\[end of libtorchcodec loading traceback\]", re.DOTALL
)


def _run_cli(args: list[str]) -> subprocess.CompletedProcess:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(args, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-5000:]
    assert "Traceback" not in TORCHCODEC_LOADING_TRACEBACK.sub("", proc.stderr), proc.stderr[-5000:]
    return proc


@pytest.fixture(scope="module")
def diffusion_checkpoint(five_cam_root, tmp_path_factory) -> Path:
    """A stock Diffusion Policy trained for 2 steps on the recorded five-camera dataset."""
    out = tmp_path_factory.mktemp("train") / "diffusion"
    _run_cli(
        [
            str(BIN / "lerobot-train"),
            f"--dataset.repo_id={REPO_ID}",
            f"--dataset.root={five_cam_root}",
            "--dataset.video_backend=pyav",
            "--policy.type=diffusion",
            "--policy.device=cpu",
            "--policy.push_to_hub=false",
            "--policy.pretrained_backbone_weights=null",
            "--policy.crop_shape=null",
            "--policy.use_separate_rgb_encoder_per_camera=false",
            "--policy.down_dims=[32,64]",
            "--policy.num_inference_steps=5",
            "--steps=2",
            "--batch_size=2",
            "--num_workers=0",
            f"--output_dir={out}",
            "--wandb.enable=false",
        ]
    )
    checkpoint = out / "checkpoints" / "last" / "pretrained_model"
    assert (checkpoint / "model.safetensors").exists()
    return checkpoint


def test_stock_diffusion_trains_on_recorded_dataset(diffusion_checkpoint):
    """LeRobot makes the default per-frame calibration columns STATE inputs of a stock policy; constant
    over one rig's dataset (min == max), their normalisation stays finite, and DP reads only
    ``observation.state`` and the images (its conditioning does not grow with them)."""
    config = json.loads((diffusion_checkpoint / "config.json").read_text())
    key = extrinsics_key("cam_a")
    assert config["input_features"][key] == {"type": "STATE", "shape": [16]}
    stats = load_file(
        next(diffusion_checkpoint.glob("policy_preprocessor_step_*_normalizer_processor.safetensors"))
    )
    assert torch.equal(stats[f"{key}.min"], stats[f"{key}.max"])  # constant columns
    policy = DiffusionPolicy.from_pretrained(diffusion_checkpoint)
    per_step = len(STATE_NAMES) + len(CAMERAS) * policy.diffusion.rgb_encoder.feature_dim
    cond_dim = policy.config.diffusion_step_embed_dim + per_step * policy.config.n_obs_steps
    assert policy.diffusion.unet.down_modules[0][0].cond_encoder[1].in_features == cond_dim
    assert all(torch.isfinite(p).all() for p in policy.parameters())  # trained without NaN


def test_stock_lerobot_eval_runs_omnid_env_and_writes_video(diffusion_checkpoint, tmp_path):
    """The env's default observation carries the per-frame calibration the checkpoint was trained with."""
    out = tmp_path / "eval"
    _run_cli(
        [
            str(BIN / "lerobot-eval"),
            "--env.type=omnid",
            "--env.task=select_apple",
            "--env.layout=position_ood",
            f"--env.cameras=[{','.join(CAMERAS)}]",
            f"--env.image_size={SIZE}",
            "--env.episode_length=10",
            f"--policy.path={diffusion_checkpoint}",
            "--eval.n_episodes=1",
            "--eval.batch_size=1",
            "--policy.device=cpu",
            f"--output_dir={out}",
        ]
    )
    videos = list((out / "videos").rglob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0
    overall = json.loads((out / "eval_info.json").read_text())["overall"]
    assert overall["n_episodes"] == 1 and 0 <= overall["pc_success"] <= 100
