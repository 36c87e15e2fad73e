"""``--env.type=omnid``: the env config's features, validation, CLI parsing and LeRobot's make_env."""

from __future__ import annotations

import os
from dataclasses import dataclass

import draccus
import numpy as np
import pytest
import torch
from gym_omnid.constants import TASKS
from gym_omnid.experts import make_expert
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.envs.factory import make_env
from lerobot.envs.utils import env_to_policy_features, preprocess_observation
from lerobot.processor import (
    PolicyProcessorPipeline,
    policy_action_to_transition,
    transition_to_policy_action,
)
from lerobot.scripts.lerobot_eval import rollout

from lerobot_omnid.calibration.frame_columns import extrinsics_from_column
from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.env_config import OmniDEnvConfig

os.environ.setdefault("MUJOCO_GL", "egl")

STATE_DIM = 16
ACTION_DIM = 10


def test_registered_and_defaults():
    assert EnvConfig.get_choice_class("omnid") is OmniDEnvConfig
    cfg = OmniDEnvConfig()
    assert cfg.type == "omnid"
    assert cfg.gym_id == "gym_omnid/select_apple"
    assert cfg.cameras == ["cam_b", "cam_c", "cam_d", "cam_e"]
    assert cfg.fps == 10
    assert cfg.image_size == 128


def test_features_for_camera_subset():
    cfg = OmniDEnvConfig(
        task="select_chemistry_tube",
        cameras=["cam_a", "cam_c"],
        image_size=64,
        layout="position_ood",
        background="ood2",
        episode_length=30,
    )
    # The default observation carries every camera's per-frame calibration (omnid-record's columns).
    columns = {
        f"{kind}.{cam}": f"observation.{kind}.{cam}"
        for cam in ("cam_a", "cam_c")
        for kind in ("extrinsics", "intrinsics")
    }
    assert cfg.features_map == {
        "action": "action",
        "agent_pos": "observation.state",
        "pixels/cam_a": "observation.images.cam_a",
        "pixels/cam_c": "observation.images.cam_c",
        **columns,
    }
    assert {k: (f.type, f.shape) for k, f in cfg.features.items()} == {
        "action": (FeatureType.ACTION, (ACTION_DIM,)),
        "agent_pos": (FeatureType.STATE, (STATE_DIM,)),
        "pixels/cam_a": (FeatureType.VISUAL, (64, 64, 3)),
        "pixels/cam_c": (FeatureType.VISUAL, (64, 64, 3)),
        **{k: (FeatureType.STATE, (16 if k.startswith("extrinsics") else 9,)) for k in columns},
    }
    without = OmniDEnvConfig(cameras=["cam_a", "cam_c"], per_frame_calibration=False)
    assert sorted(without.features_map) == ["action", "agent_pos", "pixels/cam_a", "pixels/cam_c"]
    policy_features = env_to_policy_features(cfg)
    assert policy_features["observation.images.cam_c"].shape == (3, 64, 64)
    assert policy_features["observation.state"].shape == (STATE_DIM,)
    assert cfg.gym_id == "gym_omnid/select_chemistry_tube"
    assert cfg.gym_kwargs == {
        "cameras": ("cam_a", "cam_c"),
        "layout": "position_ood",
        "background": "ood2",
        "image_size": 64,
        "rig": "default",
        "per_frame_calibration": True,
        "blackout_cameras": (),
        "blackout_from_step": 0,
        "camera_offsets": {},
        "task_onehot": False,
        "render_mode": "rgb_array",
        "max_episode_steps": 30,
    }


@pytest.mark.parametrize(
    ("kwargs", "field_name", "actual"),
    [
        ({"task": "make_tea"}, "task", "'make_tea'"),
        ({"cameras": ["cam_b", "cam_z"]}, "cameras", "cam_z"),
        ({"cameras": []}, "cameras", "[]"),
        ({"cameras": ["cam_b", "cam_b"]}, "cameras", "['cam_b', 'cam_b']"),
        ({"layout": "far"}, "layout", "'far'"),
        ({"background": "ood5"}, "background", "'ood5'"),
        ({"image_size": 0}, "image_size", "0"),
        ({"rig": "lab9"}, "rig", "'lab9'"),
        ({"per_frame_calibration": "yes"}, "per_frame_calibration", "'yes'"),
        ({"task_onehot": 1}, "task_onehot", "1"),
        ({"blackout_cameras": ["cam_a"]}, "blackout_cameras", "['cam_a']"),
        ({"blackout_cameras": ["cam_b", "cam_b"]}, "blackout_cameras", "['cam_b', 'cam_b']"),
        ({"blackout_cameras": "cam_b"}, "blackout_cameras", "'cam_b'"),
        ({"blackout_from_step": 5}, "blackout_from_step", "5"),
        ({"blackout_from_step": -1, "blackout_cameras": ["cam_b"]}, "blackout_from_step", "-1"),
        ({"camera_offsets": {"cam_z": [0] * 6}}, "camera_offsets", "'cam_z'"),
        ({"camera_offsets": {"cam_b": [0, 0, 1]}}, r"camera_offsets\[cam_b\]", "[0, 0, 1]"),
        ({"episode_length": 0}, "episode_length", "0"),
        ({"fps": 30}, "fps", "30"),
        ({"render_mode": "human"}, "render_mode", "'human'"),
    ],
)
def test_validation_names_field_and_value(kwargs, field_name, actual):
    with pytest.raises(ValueError, match=field_name) as err:
        OmniDEnvConfig(**kwargs)
    assert actual in str(err.value)
    assert "expected" in str(err.value)


def test_cli_parsing_of_camera_list():
    @dataclass
    class Cli:
        env: EnvConfig

    args = ["--env.type=omnid", "--env.cameras=[cam_b,cam_c]", "--env.image_size=64"]
    cfg = draccus.parse(Cli, args=[*args, "--env.blackout_cameras=[cam_c]"])
    assert isinstance(cfg.env, OmniDEnvConfig)
    assert cfg.env.cameras == ["cam_b", "cam_c"] and cfg.env.blackout_cameras == ["cam_c"]
    assert cfg.env.gym_kwargs["blackout_cameras"] == ("cam_c",)
    columns = {f"{kind}.{cam}" for cam in ("cam_b", "cam_c") for kind in ("extrinsics", "intrinsics")}
    assert set(cfg.env.features) == {"action", "agent_pos", "pixels/cam_b", "pixels/cam_c", *columns}
    # The robustness options: a camera dying mid-episode, a bumped camera.
    robust = ["--env.blackout_from_step=7", '--env.camera_offsets={"cam_b":[0,0,2,0.02,0,0]}']
    cfg = draccus.parse(Cli, args=[*args, "--env.blackout_cameras=[cam_c]", *robust])
    assert cfg.env.gym_kwargs["blackout_from_step"] == 7
    assert cfg.env.gym_kwargs["camera_offsets"] == {"cam_b": (0.0, 0.0, 2.0, 0.02, 0.0, 0.0)}


def test_make_env_builds_and_steps():
    cfg = OmniDEnvConfig(cameras=["cam_b", "cam_d"], image_size=64, episode_length=3)
    envs = make_env(cfg, n_envs=1)
    vec = envs["omnid"][0]
    try:
        obs, _ = vec.reset(seed=[0])
        assert vec.call("_max_episode_steps")[0] == 3
        assert isinstance(vec.call("task_description")[0], str)
        assert vec.unwrapped.metadata["render_fps"] == 10
        batch = preprocess_observation(obs)
        assert batch["observation.images.cam_b"].shape == (1, 3, 64, 64)
        assert batch["observation.state"].shape == (1, STATE_DIM)
        # The state starts with the TCP pose and gripper in the action's layout: hold still.
        action = obs["agent_pos"][:, :ACTION_DIM]
        for _ in range(3):
            obs, _, terminated, truncated, info = vec.step(action.astype(np.float32))
            assert "is_success" in info or "final_info" in info
        assert truncated[0] or terminated[0]
        frame = vec.envs[0].render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    finally:
        vec.close()


def test_camera_calibrations_are_valid_for_image_size():
    cfg = OmniDEnvConfig(cameras=["cam_a", "cam_e"], image_size=64)
    calibs = cfg.camera_calibrations()
    assert sorted(calibs) == ["observation.images.cam_a", "observation.images.cam_e"]
    for key, data in calibs.items():
        calib = CameraCalibration.from_dict(data, camera=key)
        assert calib.image_size == (64, 64)


class _ExpertPolicy(torch.nn.Module):
    """Drives the scripted expert of sub-env 0 through LeRobot's policy interface."""

    def __init__(self, vec):
        super().__init__()
        self.vec, self.expert = vec, None

    def reset(self):
        self.expert = None

    def select_action(self, batch):
        if self.expert is None:
            self.expert = make_expert(self.vec.envs[0].unwrapped)
        return torch.from_numpy(self.expert.act()).float()[None]


def test_lerobot_rollout_counts_expert_success():
    """``lerobot-eval``'s own rollout reads ``is_success`` from our env: the expert scores a success."""
    cfg = OmniDEnvConfig(cameras=["cam_c"], image_size=32)
    vec = make_env(cfg, n_envs=1)["omnid"][0]
    identity = PolicyProcessorPipeline(steps=[])
    actions = PolicyProcessorPipeline(
        steps=[], to_transition=policy_action_to_transition, to_output=transition_to_policy_action
    )
    try:
        result = rollout(vec, _ExpertPolicy(vec), identity, identity, identity, actions, seeds=[0])
    finally:
        vec.close()
    assert result["success"].any()
    assert result["done"][0, -1] and result["action"].shape[1] < cfg.episode_length


def test_rig_and_per_frame_calibration_reach_the_policy_batch():
    """``--env.rig`` and ``--env.per_frame_calibration``: lerobot-eval's batch carries each camera's
    calibration of the frame under the dataset columns' names, unnormalised, the rig's own."""

    @dataclass
    class Cli:
        env: EnvConfig

    args = ["--env.type=omnid", "--env.cameras=[cam_b,cam_wrist]", "--env.image_size=32"]
    cfg = draccus.parse(Cli, args=[*args, "--env.rig=bumped", "--env.per_frame_calibration=true"]).env
    assert (cfg.rig, cfg.per_frame_calibration) == ("bumped", True)
    assert cfg.features_map["extrinsics.cam_wrist"] == "observation.extrinsics.cam_wrist"
    assert cfg.features_map["intrinsics.cam_b"] == "observation.intrinsics.cam_b"
    policy_features = env_to_policy_features(cfg)
    assert policy_features["observation.extrinsics.cam_b"].shape == (16,)
    assert policy_features["observation.intrinsics.cam_wrist"].shape == (9,)
    vec = make_env(cfg, n_envs=1)["omnid"][0]
    try:
        obs, _ = vec.reset(seed=[0])
        batch = preprocess_observation(obs)
        env = vec.envs[0].unwrapped
        assert env.rig == "bumped"
        for cam in ("cam_b", "cam_wrist"):
            calib = env.camera_calibration(cam)
            T_cam_world = extrinsics_from_column(batch[f"observation.extrinsics.{cam}"])
            assert T_cam_world.shape == (1, 4, 4)
            np.testing.assert_allclose(T_cam_world[0].numpy(), calib["T_cam_world"], atol=1e-6)
            K = batch[f"observation.intrinsics.{cam}"].reshape(1, 3, 3)
            np.testing.assert_allclose(K[0].numpy(), calib["K"], rtol=1e-6)
    finally:
        vec.close()
    with pytest.raises(ValueError, match="cam_wrist moves with the arm"):
        cfg.camera_calibrations()


def test_task_onehot_reaches_the_policy_batch():
    """``--env.task_onehot``: lerobot-eval's batch carries the task as a one-hot over the six tasks, under
    ``observation.environment_state`` typed ENV (what LeRobot's DP and ACT and OmniD condition on)."""

    @dataclass
    class Cli:
        env: EnvConfig

    args = ["--env.type=omnid", "--env.task=get_coffee", "--env.cameras=[cam_b]", "--env.image_size=32"]
    cfg = draccus.parse(Cli, args=[*args, "--env.task_onehot=true", "--env.episode_length=2"]).env
    assert cfg.gym_kwargs["task_onehot"] is True
    assert cfg.features_map["environment_state"] == "observation.environment_state"
    assert env_to_policy_features(cfg)["observation.environment_state"] == PolicyFeature(
        FeatureType.ENV, (len(TASKS),)
    )
    assert "environment_state" not in OmniDEnvConfig(cameras=["cam_b"]).features  # off by default
    expected = np.zeros((1, len(TASKS)), dtype=np.float32)
    expected[0, TASKS.index("get_coffee")] = 1.0
    vec = make_env(cfg, n_envs=1)["omnid"][0]
    try:
        obs, _ = vec.reset(seed=[0])
        np.testing.assert_array_equal(preprocess_observation(obs)["observation.environment_state"], expected)
        obs, *_ = vec.step(obs["agent_pos"][:, :ACTION_DIM].astype(np.float32))
        np.testing.assert_array_equal(preprocess_observation(obs)["observation.environment_state"], expected)
    finally:
        vec.close()
