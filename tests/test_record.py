"""``omnid-record``: datasets that load, carry calibration, names and task text, keep only successful
episodes, are reproducible, survive Ctrl-C, and train and evaluate with the stock LeRobot CLIs."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import gym_omnid.experts
import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
import torch
from gym_omnid.constants import ACTION_NAMES, CAMERAS, STATE_NAMES
from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
from safetensors.torch import load_file

from lerobot_omnid.calibration.frame_columns import (
    extrinsics_column,
    extrinsics_key,
    intrinsics_column,
    intrinsics_key,
    is_calibration_key,
)
from lerobot_omnid.calibration.schema import CALIBRATION_INFO_KEY, calibration_from_feature_info
from lerobot_omnid.env_config import OmniDEnvConfig
from lerobot_omnid.record import EXIT_INTERRUPTED, main, record_dataset

SIZE = 64
REPO_ID = "local/omnid_select_apple"
APPLE_INSTRUCTION = "put the apple in the bowl"
BIN = Path(sys.executable).parent


def _load(root: Path, repo_id: str = REPO_ID) -> LeRobotDataset:
    return LeRobotDataset(repo_id, root=root, video_backend="pyav")


def _read_data(root: Path, columns: list[str]) -> pd.DataFrame:
    files = sorted((root / "data").rglob("*.parquet"))
    return pd.concat([pd.read_parquet(f, columns=columns) for f in files], ignore_index=True)


def _state_action(root: Path) -> pd.DataFrame:
    return _read_data(root, ["episode_index", "observation.state", "action"])


def _assert_only_dataset_dirs(root: Path) -> None:
    """Nothing half-written: no staging images or temporary encoder folders left behind."""
    assert sorted(p.name for p in root.iterdir()) == ["data", "meta", "videos"]


class _PatchedExperts:
    """Wrap ``make_expert`` so that chosen attempts (1-based) stall or raise KeyboardInterrupt."""

    def __init__(self, stall=(), interrupt=None, interrupt_after_steps=5):
        self.real = gym_omnid.experts.make_expert
        self.stall, self.interrupt, self.after = set(stall), interrupt, interrupt_after_steps
        self.calls = 0

    def __call__(self, env):
        self.calls += 1
        expert = self.real(env)
        if self.calls in self.stall:
            first = expert.act()
            return type("Stalling", (), {"act": lambda _self: first})()
        if self.calls == self.interrupt:
            return _InterruptingExpert(expert, self.after)
        return expert


class _InterruptingExpert:
    def __init__(self, expert, after: int):
        self.expert, self.left = expert, after

    def act(self):
        if self.left == 0:
            raise KeyboardInterrupt
        self.left -= 1
        return self.expert.act()


def _expert_rollout_states(seed: int, episode_length: int = 200) -> np.ndarray:
    """States seen by the expert in one attempt with ``seed``, without any dataset machinery."""
    cfg = OmniDEnvConfig(cameras=["cam_b"], image_size=SIZE, episode_length=episode_length)
    env = gym.make(cfg.gym_id, disable_env_checker=True, **cfg.gym_kwargs)
    try:
        obs, _ = env.reset(seed=seed)
        expert = gym_omnid.experts.make_expert(env.unwrapped)
        states = []
        while True:
            states.append(obs["agent_pos"])
            obs, _, terminated, truncated, _ = env.step(expert.act())
            if terminated or truncated:
                return np.stack(states)
    finally:
        env.close()


@pytest.fixture(scope="module")
def five_cam_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("record") / "five_cams"
    summary = record_dataset(root, episodes=2, cameras=CAMERAS, image_size=SIZE, seed=0, show_progress=False)
    assert summary.complete and not summary.interrupted
    return root


def test_dataset_loads_with_calibrated_videos_names_and_task(five_cam_root):
    ds = _load(five_cam_root)
    assert ds.num_episodes == 2
    assert ds.fps == 10
    assert ds.meta.robot_type == "omnid_sim_arm"
    assert sorted(ds.meta.video_keys) == [f"observation.images.{cam}" for cam in CAMERAS]

    meta = LeRobotDatasetMetadata(REPO_ID, root=five_cam_root)
    expected = OmniDEnvConfig(cameras=list(CAMERAS), image_size=SIZE).camera_calibrations()
    for key in meta.video_keys:
        feature = meta.features[key]
        assert feature["dtype"] == "video" and tuple(feature["shape"]) == (SIZE, SIZE, 3)
        assert feature["info"]["video.height"] == SIZE  # video info merged
        # The default: the calibration is in every frame's columns, none in the feature info.
        assert CALIBRATION_INFO_KEY not in feature["info"]
        assert extrinsics_key(key) in meta.features and intrinsics_key(key) in meta.features

    assert meta.features["observation.state"]["names"] == list(STATE_NAMES)
    assert meta.features["action"]["names"] == list(ACTION_NAMES)
    assert meta.features["observation.state"]["dtype"] == "float32"

    frames = [ds[i] for i in (0, len(ds) - 1)]
    for item in frames:
        assert item["task"] == APPLE_INSTRUCTION
        assert item["observation.images.cam_a"].shape == (3, SIZE, SIZE)
        assert item["observation.state"].shape == (len(STATE_NAMES),)
        assert item["action"].shape == (len(ACTION_NAMES),)
        for key, calib in expected.items():
            np.testing.assert_array_equal(
                item[extrinsics_key(key)].numpy(), extrinsics_column(calib["T_cam_world"])
            )
            np.testing.assert_array_equal(item[intrinsics_key(key)].numpy(), intrinsics_column(calib["K"]))
    # Every frame's task is the env's instruction.
    assert list(meta.tasks.index) == [APPLE_INSTRUCTION]
    assert set(_read_data(five_cam_root, ["task_index"])["task_index"]) == {0}
    _assert_only_dataset_dirs(five_cam_root)


def test_failed_attempts_are_discarded_and_seeds_follow_attempts(monkeypatch, tmp_path):
    experts = _PatchedExperts(stall={1})
    monkeypatch.setattr(gym_omnid.experts, "make_expert", experts)
    summary = record_dataset(
        tmp_path / "ds",
        episodes=1,
        cameras=["cam_b"],
        image_size=SIZE,
        seed=7,
        episode_length=120,
        show_progress=False,
    )
    assert (summary.episodes, summary.attempts) == (1, 2)
    monkeypatch.undo()

    data = _state_action(tmp_path / "ds")
    assert set(data["episode_index"]) == {0}
    # The one saved episode is attempt 2, i.e. seed 7 + 1, replayed here without the recorder.
    np.testing.assert_array_equal(np.stack(data["observation.state"]), _expert_rollout_states(8, 120))
    assert summary.frames == len(data) < 120
    assert _load(tmp_path / "ds").num_episodes == 1
    _assert_only_dataset_dirs(tmp_path / "ds")


def test_same_seed_gives_same_data(tmp_path):
    kwargs = {"episodes": 2, "cameras": ["cam_d"], "image_size": SIZE, "seed": 3, "show_progress": False}
    record_dataset(tmp_path / "a", **kwargs)
    record_dataset(tmp_path / "b", **kwargs)
    a, b = _state_action(tmp_path / "a"), _state_action(tmp_path / "b")
    assert len(a) > 0
    pd.testing.assert_frame_equal(a, b)


def test_interrupt_keeps_completed_episodes(monkeypatch, tmp_path):
    monkeypatch.setattr(gym_omnid.experts, "make_expert", _PatchedExperts(interrupt=3))
    summary = record_dataset(
        tmp_path / "ds", episodes=5, cameras=["cam_b", "cam_e"], image_size=SIZE, show_progress=False
    )
    assert summary.interrupted and (summary.episodes, summary.attempts) == (2, 3)
    ds = _load(tmp_path / "ds")
    assert ds.num_episodes == 2 and ds.num_frames == summary.frames
    assert ds[len(ds) - 1]["observation.images.cam_e"].shape == (3, SIZE, SIZE)
    _assert_only_dataset_dirs(tmp_path / "ds")


def test_nothing_left_when_no_episode_succeeds(monkeypatch, tmp_path):
    summary = record_dataset(
        tmp_path / "ds",
        episodes=1,
        cameras=["cam_b"],
        image_size=SIZE,
        max_attempts=2,
        episode_length=3,
        show_progress=False,
    )
    assert (summary.episodes, summary.attempts, summary.complete) == (0, 2, False)
    assert not (tmp_path / "ds").exists()

    monkeypatch.setattr(gym_omnid.experts, "make_expert", _PatchedExperts(interrupt=1))
    summary = record_dataset(
        tmp_path / "ds2", episodes=1, cameras=["cam_b"], image_size=SIZE, show_progress=False
    )
    assert summary.interrupted and summary.episodes == 0
    assert not (tmp_path / "ds2").exists()


def test_main_records_and_prints_summary(tmp_path, capsys):
    root = tmp_path / "ds"
    assert (
        main(
            [
                "--episodes",
                "1",
                "--cameras",
                "cam_c",
                "--image-size",
                str(SIZE),
                "--root",
                str(root),
                "--repo-id",
                "me/apples",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "saved 1/1 episodes from 1 attempts" in out and "frames/s" in out and str(root) in out
    assert _load(root, "me/apples").num_episodes == 1


def test_static_calibration_flag_writes_the_feature_info(tmp_path):
    """``--static-calibration``: the older form, each camera's calibration once in its feature info."""
    root = tmp_path / "ds"
    argv = ["--episodes", "1", "--cameras", "cam_b,cam_c", "--image-size", str(SIZE), "--static-calibration"]
    assert main([*argv, "--root", str(root), "--repo-id", "me/static"]) == 0
    meta = LeRobotDatasetMetadata("me/static", root=root)
    expected = OmniDEnvConfig(cameras=["cam_b", "cam_c"], image_size=SIZE).camera_calibrations()
    for key in meta.video_keys:
        feature = meta.features[key]
        assert feature["info"]["video.height"] == SIZE  # video info merged, calibration kept
        calib = calibration_from_feature_info(key, feature)
        assert calib.image_size == (SIZE, SIZE)
        assert calib.to_dict() == expected[key]
    assert not any(is_calibration_key(key) for key in meta.features)
    assert _load(root, "me/static").num_episodes == 1


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--task", "make_tea"], ["--task", "make_tea", "select_apple"]),
        (["--cameras", "cam_b,cam_z"], ["--cameras", "cam_z", "cam_a"]),
        (["--layout", "far"], ["--layout", "far", "position_ood"]),
        (["--background", "ood9"], ["--background", "ood9", "ood4"]),
        (["--episodes", "0"], ["--episodes", ">= 1", "0"]),
        (["--image-size", "-1"], ["--image-size", "-1"]),
        (["--image-size", "5000"], ["--image-size", "2048", "5000"]),
        (["--rig", "lab9"], ["--rig", "lab9", "bumped"]),
        (["--cameras", "cam_b,cam_wrist", "--static-calibration"], ["cam_wrist", "--static-calibration"]),
        (
            ["--per-frame-calibration", "--static-calibration"],
            ["--static-calibration", "--per-frame-calibration"],
        ),
        (["--episodes", "3", "--max-attempts", "2"], ["--max-attempts", "3", "2"]),
        (["--push-to-hub"], ["--repo-id", "namespace", "local/omnid_select_apple"]),
    ],
)
def test_bad_arguments_are_named(argv, expected, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--root", str(tmp_path / "ds")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    for text in expected:
        assert text in err
    assert not (tmp_path / "ds").exists()


def test_refuses_to_overwrite_non_empty_root(tmp_path, capsys):
    root = tmp_path / "ds"
    root.mkdir()
    (root / "keep.txt").write_text("mine")
    with pytest.raises(SystemExit):
        main(["--episodes", "1", "--root", str(root)])
    err = capsys.readouterr().err
    assert "--root" in err and "refusing to overwrite" in err
    assert (root / "keep.txt").read_text() == "mine"
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        record_dataset(root, episodes=1)


def test_record_dataset_rejects_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="`episodes`: expected a positive integer, got 0"):
        record_dataset(tmp_path / "a", episodes=0)
    with pytest.raises(ValueError, match="cameras: unknown camera"):
        record_dataset(tmp_path / "a", episodes=1, cameras=["cam_q"])
    with pytest.raises(ValueError, match="`task`: expected one of"):
        record_dataset(tmp_path / "a", episodes=1, task="make_tea")
    assert not (tmp_path / "a").exists()


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
    ds = _load(root)
    assert 1 <= ds.num_episodes < 50
    assert ds[len(ds) - 1]["observation.images.cam_b"].shape == (3, SIZE, SIZE)
    _assert_only_dataset_dirs(root)


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
