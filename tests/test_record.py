"""``omnid-record``: datasets that load, carry calibration, names and task text, keep only successful
episodes, are reproducible and survive an interrupt. (The console command's Ctrl-C and the stock LeRobot
CLIs on a recording: tests/e2e/test_omnid_record.py.)"""

from __future__ import annotations

import sys
from pathlib import Path

import gym_omnid.experts
import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from gym_omnid.constants import ACTION_NAMES, CAMERAS, STATE_NAMES, TASKS
from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
from lerobot.envs.utils import env_to_policy_features
from lerobot.scripts.lerobot_edit_dataset import edit_dataset
from lerobot.utils.constants import OBS_ENV_STATE
from lerobot.utils.feature_utils import dataset_to_policy_features
from omnid_testing import assert_only_dataset_dirs, load_recording, record_five_cameras

from lerobot_omnid.calibration.frame_columns import (
    extrinsics_column,
    extrinsics_key,
    intrinsics_column,
    intrinsics_key,
    is_calibration_key,
)
from lerobot_omnid.calibration.schema import CALIBRATION_INFO_KEY, calibration_from_feature_info
from lerobot_omnid.camera_visibility import CAMERA_VISIBLE_KEY
from lerobot_omnid.env_config import OmniDEnvConfig
from lerobot_omnid.record import main, record_dataset

SIZE = 64
REPO_ID = "local/omnid_select_apple"  # omnid-record's default for select_apple
APPLE_INSTRUCTION = "put the apple in the bowl"


def _read_data(root: Path, columns: list[str]) -> pd.DataFrame:
    files = sorted((root / "data").rglob("*.parquet"))
    return pd.concat([pd.read_parquet(f, columns=columns) for f in files], ignore_index=True)


def _state_action(root: Path) -> pd.DataFrame:
    return _read_data(root, ["episode_index", "observation.state", "action"])


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
    return record_five_cameras(tmp_path_factory.mktemp("record") / "five_cams", SIZE)


def test_dataset_loads_with_calibrated_videos_names_and_task(five_cam_root):
    ds = load_recording(five_cam_root)
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
    assert CAMERA_VISIBLE_KEY not in meta.features  # only with --hidden-cameras

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
    assert_only_dataset_dirs(five_cam_root)


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
    assert load_recording(tmp_path / "ds").num_episodes == 1
    assert_only_dataset_dirs(tmp_path / "ds")


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
    ds = load_recording(tmp_path / "ds")
    assert ds.num_episodes == 2 and ds.num_frames == summary.frames
    assert ds[len(ds) - 1]["observation.images.cam_e"].shape == (3, SIZE, SIZE)
    assert_only_dataset_dirs(tmp_path / "ds")


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
    assert load_recording(root, "me/apples").num_episodes == 1


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
    assert load_recording(root, "me/static").num_episodes == 1


def test_task_onehot_datasets_of_two_tasks_share_features_and_merge(tmp_path, monkeypatch):
    """``--task-onehot``: each frame's ``observation.environment_state`` is its task's one-hot, the feature
    spec is the same for every task, and LeRobot's own ``lerobot-edit-dataset`` merge (its argument parsing
    and merge, run in this process) makes one dataset of two tasks, each episode keeping its one-hot."""
    tasks = ("select_apple", "add_condiment")
    roots = [tmp_path / task for task in tasks]
    for task, root in zip(tasks, roots, strict=True):
        argv = [
            "--task",
            task,
            "--episodes",
            "1",
            "--cameras",
            "cam_b",
            "--image-size",
            "32",
            "--task-onehot",
        ]
        assert main([*argv, "--root", str(root), "--repo-id", f"local/{task}"]) == 0
    metas = [
        LeRobotDatasetMetadata(f"local/{task}", root=root) for task, root in zip(tasks, roots, strict=True)
    ]
    assert metas[0].features == metas[1].features  # info of every feature included
    assert metas[0].features[OBS_ENV_STATE] == {"dtype": "float32", "shape": (6,), "names": list(TASKS)}
    # The dataset's feature is the one lerobot-eval gives a policy with --env.task_onehot=true.
    env_cfg = OmniDEnvConfig(cameras=["cam_b"], image_size=32, task_onehot=True)
    assert (
        dataset_to_policy_features(metas[0].features)[OBS_ENV_STATE]
        == env_to_policy_features(env_cfg)[OBS_ENV_STATE]
    )
    onehots = np.eye(len(TASKS), dtype=np.float32)
    for task, root in zip(tasks, roots, strict=True):
        column = np.stack(_read_data(root, [OBS_ENV_STATE])[OBS_ENV_STATE])
        assert column.dtype == np.float32 and len(column) > 0
        np.testing.assert_array_equal(column, np.broadcast_to(onehots[TASKS.index(task)], column.shape))

    merged = tmp_path / "merged"
    argv = [
        "lerobot-edit-dataset",
        "--new_repo_id=local/merged",
        f"--new_root={merged}",
        "--operation.type=merge",
        f"--operation.repo_ids={[f'local/{task}' for task in tasks]}",
        f"--operation.roots={[str(root) for root in roots]}",
    ]
    monkeypatch.setattr(sys, "argv", argv)
    edit_dataset()
    data = _read_data(merged, ["episode_index", OBS_ENV_STATE])
    for episode, task in enumerate(tasks):
        column = np.stack(data[data.episode_index == episode][OBS_ENV_STATE])
        np.testing.assert_array_equal(column, np.broadcast_to(onehots[TASKS.index(task)], column.shape))
    item = load_recording(merged, "local/merged")[len(data) - 1]
    np.testing.assert_array_equal(item[OBS_ENV_STATE].numpy(), onehots[TASKS.index(tasks[1])])


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
        (["--suite", "metaworld", "--task", "assembly-v3", "--task-onehot"], ["--task-onehot", "metaworld"]),
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
    with pytest.raises(ValueError, match="task_onehot: the metaworld suite has no variants; expected False"):
        record_dataset(tmp_path / "a", suite="metaworld", task="assembly-v3", episodes=1, task_onehot=True)
    assert not (tmp_path / "a").exists()
