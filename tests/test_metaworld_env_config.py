"""``--env.type=omnid_metaworld`` and ``omnid-record --suite metaworld``: the env config's features,
validation, CLI parsing and LeRobot's make_env; the recorder's suite arguments."""

from __future__ import annotations

from dataclasses import dataclass

import draccus
import numpy as np
import pytest
from gym_omnid.metaworld_suite import DEFAULT_CAMERAS, STATE_DIM
from lerobot.envs.configs import EnvConfig

from lerobot_omnid.env_config_metaworld import OmniDMetaWorldEnvConfig
from lerobot_omnid.record import main

try:  # at collection: importing metaworld (gymnasium's MuJoCo renderer, glfw) starts a subprocess
    import metaworld
except ImportError:
    metaworld = None

needs_metaworld = pytest.mark.skipif(metaworld is None, reason="needs the optional dependency metaworld")
SIZE = 32


def test_registered_and_defaults() -> None:
    assert EnvConfig.get_choice_class("omnid_metaworld") is OmniDMetaWorldEnvConfig
    cfg = OmniDMetaWorldEnvConfig()
    assert cfg.type == "omnid_metaworld" and cfg.task == "assembly-v3"
    assert cfg.gym_id == "gym_omnid_metaworld/assembly-v3"
    assert cfg.package_name == "gym_omnid.metaworld_suite"
    assert cfg.cameras == list(DEFAULT_CAMERAS) and cfg.fps == 80 and cfg.episode_length == 500


def test_cli_parsing_features_and_kwargs() -> None:
    @dataclass
    class Cli:
        env: EnvConfig

    args = ["--env.type=omnid_metaworld", "--env.task=stick-push-v3", "--env.cameras=[corner,gripperPOV]"]
    cfg = draccus.parse(Cli, args=[*args, f"--env.image_size={SIZE}", "--env.episode_length=7"]).env
    assert isinstance(cfg, OmniDMetaWorldEnvConfig)
    columns = {f"{kind}.{cam}" for cam in ("corner", "gripperPOV") for kind in ("extrinsics", "intrinsics")}
    assert set(cfg.features) == {"action", "agent_pos", "pixels/corner", "pixels/gripperPOV", *columns}
    assert cfg.features["agent_pos"].shape == (STATE_DIM,) and cfg.features["action"].shape == (4,)
    assert cfg.features["pixels/corner"].shape == (SIZE, SIZE, 3)
    assert cfg.features_map["pixels/gripperPOV"] == "observation.images.gripperPOV"
    assert cfg.features_map["extrinsics.gripperPOV"] == "observation.extrinsics.gripperPOV"
    assert cfg.gym_kwargs == {
        "cameras": ("corner", "gripperPOV"),
        "image_size": SIZE,
        "per_frame_calibration": True,
        "blackout_cameras": (),
        "render_mode": "rgb_array",
        "max_episode_steps": 7,
    }


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"task": "select_apple"}, "`task`: expected one of ['assembly-v3'"),
        ({"cameras": ["cam_b"]}, "cameras: unknown camera(s) ['cam_b']; expected names from ['corner'"),
        ({"image_size": 0}, "image_size: expected an int number of pixels"),
        ({"fps": 10}, "fps: MetaWorld steps at a fixed 80 Hz"),
        ({"episode_length": 0}, "`episode_length`: expected a positive integer"),
        ({"blackout_cameras": ["cam_b"]}, "blackout_cameras: expected distinct cameras among the observed"),
    ],
)
def test_bad_fields_are_named(kwargs: dict, expected: str) -> None:
    with pytest.raises(ValueError) as err:
        OmniDMetaWorldEnvConfig(**kwargs)
    assert expected in str(err.value)


@needs_metaworld
def test_make_env_builds_steps_and_maps_keys() -> None:
    from lerobot.envs.factory import make_env
    from lerobot.envs.utils import preprocess_observation

    cfg = OmniDMetaWorldEnvConfig(task="push-v3", image_size=SIZE, episode_length=3)
    vec = make_env(cfg, n_envs=1)["omnid_metaworld"][0]
    try:
        obs, _ = vec.reset(seed=[0])
        assert vec.call("_max_episode_steps")[0] == 3
        assert vec.call("task_description")[0] == "push"
        batch = preprocess_observation(obs)
        for cam in DEFAULT_CAMERAS:
            assert batch[f"observation.images.{cam}"].shape == (1, 3, SIZE, SIZE)
            assert batch[f"observation.extrinsics.{cam}"].shape == (1, 16)
        assert batch["observation.state"].shape == (1, STATE_DIM)
        for _ in range(3):
            obs, _, terminated, truncated, _ = vec.step(np.zeros((1, 4), np.float32))
        assert truncated[0] or terminated[0]
    finally:
        vec.close()


@needs_metaworld
def test_camera_calibrations_of_fixed_cameras_only() -> None:
    calibs = OmniDMetaWorldEnvConfig(task="push-v3", cameras=["corner", "corner3"], image_size=SIZE)
    assert sorted(calibs.camera_calibrations()) == ["observation.images.corner", "observation.images.corner3"]
    with pytest.raises(ValueError, match=r"\['behindGripper'\] move with the hand"):
        OmniDMetaWorldEnvConfig(task="push-v3").camera_calibrations()


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--suite", "metaworld"], ["--task", "--suite metaworld needs a task", "assembly-v3"]),
        (["--suite", "metaworld", "--task", "select_apple"], ["--task", "select_apple", "assembly-v3"]),
        (["--task", "assembly-v3"], ["--task", "assembly-v3", "select_apple"]),
        (
            ["--suite", "metaworld", "--task", "push-v3", "--cameras", "cam_b"],
            ["--cameras", "cam_b", "corner"],
        ),
        (
            ["--suite", "metaworld", "--task", "push-v3", "--layout", "position_ood"],
            ["--layout", "no variants"],
        ),
        (["--suite", "metaworld", "--task", "push-v3", "--rig", "bumped"], ["--rig", "no variants"]),
        (
            [
                "--suite",
                "metaworld",
                "--task",
                "push-v3",
                "--cameras",
                "corner,gripperPOV",
                "--static-calibration",
            ],
            ["gripperPOV moves with the arm", "--static-calibration"],
        ),
        (["--suite", "robosuite"], ["--suite", "robosuite", "metaworld"]),
    ],
)
def test_record_suite_arguments_are_named(argv, expected, tmp_path, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--episodes", "1", "--root", str(tmp_path / "ds")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    for text in expected:
        assert text in err
    assert not (tmp_path / "ds").exists()
