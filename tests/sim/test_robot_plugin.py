"""The sim robot (``--robot.type=omnid_sim``) and the expert teleoperator (``--teleop.type=omnid_expert``)
as LeRobot plugins: registration through our distribution, features, connection errors, actions, the
expert solving select_apple, the calibration file of the sim cameras. (The real-robot path of
``examples/09_real_robot_path.sh``: tests/e2e/test_real_robot_path.py.)"""

from __future__ import annotations

import importlib
import json
import re

import draccus
import gymnasium as gym
import numpy as np
import pytest
from gym_omnid.constants import ACTION_NAMES, MAX_EPISODE_STEPS, STATE_NAMES
from lerobot.robots.config import RobotConfig
from lerobot.robots.utils import make_robot_from_config
from lerobot.teleoperators.config import TeleoperatorConfig
from lerobot.teleoperators.utils import make_teleoperator_from_config
from lerobot.utils.errors import DeviceAlreadyConnectedError, DeviceNotConnectedError

from lerobot_omnid.calibration.rig_file import load_calibration_file
from lerobot_omnid.robot.config_omnid_expert import OmniDExpertConfig
from lerobot_omnid.robot.config_omnid_sim import OmniDSimCameraConfig, OmniDSimConfig
from lerobot_omnid.robot.features import ACTION_KEYS, STATE_KEYS
from lerobot_omnid.robot.omnid_expert import OmniDExpert
from lerobot_omnid.robot.omnid_sim import OmniDSim
from lerobot_omnid.robot.sim_calibration import SimCalibrationConfig, export_sim_calibration
from lerobot_omnid.robot.sim_calibration import main as sim_calibration_main

SIZE = 16  # px: what the unit tests render


def small_robot(**overrides) -> OmniDSimConfig:
    cameras = {"front": OmniDSimCameraConfig(source="cam_b", width=SIZE, height=SIZE)}
    return OmniDSimConfig(**{"cameras": cameras, **overrides})


@pytest.fixture
def robot():
    sim = OmniDSim(small_robot())
    sim.connect()
    yield sim
    if sim.is_connected:
        sim.disconnect()


# --- registration and configs ---------------------------------------------------------------------
def test_our_distribution_registers_the_robot_and_the_teleoperator_for_lerobot():
    importlib.import_module("lerobot_policy_omnid")  # what LeRobot's plugin discovery imports
    assert "omnid_sim" in RobotConfig.get_known_choices()
    assert "omnid_expert" in TeleoperatorConfig.get_known_choices()
    # LeRobot's factories find the classes by naming convention (config_<name> -> <name>).
    assert type(make_robot_from_config(small_robot())) is OmniDSim
    assert type(make_teleoperator_from_config(OmniDExpertConfig())) is OmniDExpert


def test_command_line_flags_parse_into_the_configs():
    args = [
        "--robot.type=omnid_sim",
        "--robot.task=select_chemistry_tube",
        "--robot.seed=3",
        "--robot.cameras={front: {source: cam_b, width: 32, height: 24}, cam_c: {width: 32, height: 24}}",
    ]
    cfg = draccus.parse(config_class=SimCalibrationConfig, args=args).robot  # a `robot: RobotConfig` field
    assert isinstance(cfg, OmniDSimConfig) and cfg.task == "select_chemistry_tube" and cfg.seed == 3
    assert {name: cam.source for name, cam in cfg.cameras.items()} == {"front": "cam_b", "cam_c": "cam_c"}
    assert cfg.image_size == (24, 32)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"task": "stack_cubes"}, r"`task`: expected one of \[.*'select_apple'.*\], got 'stack_cubes'"),
        ({"layout": "far"}, r"`layout`: expected one of \['id', 'position_ood'.*\], got 'far'"),
        ({"background": "ood9"}, r"`background`: expected one of .*, got 'ood9'"),
        ({"seed": -1}, r"`seed`: expected an integer >= 0, got -1"),
        ({"rig": "tilted"}, r"`rig`: expected one of \['default', .*\], got 'tilted'"),
        (
            {"cameras": {"cam_wrist": OmniDSimCameraConfig()}},
            r"`cameras.cam_wrist.source`: expected one of \['cam_a', .*'cam_e'\], got 'cam_wrist'",
        ),
        ({"cameras": {}}, r"`cameras`: expected a non-empty mapping"),
        (
            {"cameras": {"front": OmniDSimCameraConfig()}},
            r"`cameras.front.source`: expected one of .*got 'front'",
        ),
        (
            {"cameras": {"cam_b": OmniDSimCameraConfig(fps=30)}},
            r"`cameras.cam_b.fps`: the sim steps at a fixed 10 Hz; expected 10, got 30",
        ),
        (
            {"cameras": {"cam_b": OmniDSimCameraConfig(width=0)}},
            r"`cameras.cam_b.width`: expected an int number of pixels in \[1, \d+\], got 0",
        ),
        (
            {"cameras": {"cam_b": OmniDSimCameraConfig(), "cam_c": OmniDSimCameraConfig(width=64)}},
            r"`cameras`: expected one image size for every camera .* got \(height, width\) \[\(128, 64\), "
            r"\(128, 128\)\]",
        ),
        (
            {
                "cameras": {
                    "a": OmniDSimCameraConfig(source="cam_b"),
                    "b": OmniDSimCameraConfig(source="cam_b"),
                }
            },
            r"`cameras`: expected distinct sources, got \['cam_b', 'cam_b'\]",
        ),
    ],
)
def test_robot_config_errors_name_field_expected_and_actual(overrides, message):
    with pytest.raises(ValueError, match=message):
        OmniDSimConfig(**overrides)


def test_teleoperator_config_errors_name_field_expected_and_actual():
    with pytest.raises(ValueError, match=r"`task`: expected one of .*, got 'nope'"):
        OmniDExpertConfig(task="nope")
    with pytest.raises(ValueError, match=r"`seed`: expected an integer >= 0, got True"):
        OmniDExpertConfig(seed=True)


# --- features -------------------------------------------------------------------------------------
def test_features_follow_lerobot_robot_conventions_before_connecting():
    sim = OmniDSim(small_robot())
    assert not sim.is_connected
    assert list(sim.action_features) == list(ACTION_KEYS)
    assert all(t is float for t in sim.action_features.values())
    assert list(sim.observation_features) == [*STATE_KEYS, "front"]
    assert sim.observation_features["front"] == (SIZE, SIZE, 3)
    # lerobot-rollout keeps only scalar features named *.pos / *.vel for the policy's state and action.
    assert all(k.endswith(".pos") for k in (*STATE_KEYS, *ACTION_KEYS))
    assert len(STATE_KEYS) == len(STATE_NAMES) and len(ACTION_KEYS) == len(ACTION_NAMES)
    assert STATE_KEYS[: len(ACTION_KEYS)] == ACTION_KEYS and "shoulder_pan.pos" in STATE_KEYS
    expert = OmniDExpert(OmniDExpertConfig())
    assert expert.action_features == sim.action_features and expert.feedback_features == {}
    assert len(sim.cameras) == 1 and sim.is_calibrated and expert.is_calibrated


# --- connection -----------------------------------------------------------------------------------
def test_robot_connection_errors():
    sim = OmniDSim(small_robot())
    for call in (sim.get_observation, sim.disconnect, lambda: sim.send_action({})):
        with pytest.raises(DeviceNotConnectedError):
            call()
    with pytest.raises(DeviceNotConnectedError):
        sim.camera_calibration("front")
    sim.connect()
    with pytest.raises(DeviceAlreadyConnectedError):
        sim.connect()
    sim.disconnect()
    assert not sim.is_connected
    with pytest.raises(DeviceNotConnectedError):
        sim.get_observation()


def test_teleoperator_connection_errors():
    expert = OmniDExpert(OmniDExpertConfig())
    with pytest.raises(DeviceNotConnectedError):
        expert.get_action()
    expert.connect()
    with pytest.raises(DeviceAlreadyConnectedError):
        expert.connect()
    expert.disconnect()
    with pytest.raises(DeviceNotConnectedError):
        expert.disconnect()


# --- observation and action -----------------------------------------------------------------------
def test_observation_is_the_env_state_and_the_named_cameras_images(robot):
    obs = robot.get_observation()
    assert set(obs) == set(robot.observation_features)
    assert all(isinstance(obs[k], float) for k in STATE_KEYS)
    image = obs["front"]
    assert image.shape == (SIZE, SIZE, 3) and image.dtype == np.uint8 and image.std() > 0
    env = gym.make("gym_omnid/select_apple", cameras=("cam_b",), image_size=SIZE, disable_env_checker=True)
    try:
        env_obs, _ = env.reset(seed=robot.config.seed)  # the same scene, as the env gives it
    finally:
        env.close()
    np.testing.assert_array_equal(image, env_obs["pixels"]["cam_b"])
    np.testing.assert_allclose([obs[k] for k in STATE_KEYS], env_obs["agent_pos"], atol=1e-6)


def test_send_action_moves_the_arm_and_returns_the_applied_action(robot):
    start = robot.get_observation()
    target = {k: start[k] for k in ACTION_KEYS} | {"ee_z.pos": start["ee_z.pos"] - 0.05, "gripper.pos": 1.0}
    for _ in range(10):
        applied = robot.send_action(target)
    assert applied == pytest.approx(target, abs=1e-6)
    now = robot.get_observation()
    assert now["ee_z.pos"] == pytest.approx(target["ee_z.pos"], abs=0.01)
    assert now["gripper.pos"] > start["gripper.pos"] + 0.5  # the fingers closed
    assert robot.steps == 10
    # Out of the action space: clipped, and the clipped value is returned.
    assert robot.send_action(target | {"ee_x.pos": 5.0})["ee_x.pos"] == pytest.approx(1.0)


def test_send_action_takes_the_observed_pos_values_as_lerobots_return_to_initial_position_sends(robot):
    initial = {k: v for k, v in robot.get_observation().items() if k.endswith(".pos")}
    assert set(initial) == set(STATE_KEYS)
    applied = robot.send_action(initial)  # the joint angles are not commands: ignored
    assert set(applied) == set(ACTION_KEYS)


def test_send_action_errors_name_the_keys_and_values(robot):
    action = dict.fromkeys(ACTION_KEYS, 0.0)
    with pytest.raises(ValueError, match=r"action: expected the keys .*; missing \['gripper.pos'\]"):
        robot.send_action({k: v for k, v in action.items() if k != "gripper.pos"})
    with pytest.raises(ValueError, match=r"; unknown \['elbow_flex.pos'\]"):
        robot.send_action(action | {"elbow_flex.pos": 0.0})
    with pytest.raises(ValueError, match=r"action\['ee_x.pos'\]: expected a finite number, got nan"):
        robot.send_action(action | {"ee_x.pos": float("nan")})
    with pytest.raises(ValueError, match=r"action\['ee_y.pos'\]: expected a number, got 'left'"):
        robot.send_action(action | {"ee_y.pos": "left"})
    assert robot.steps == 0


@pytest.mark.parametrize("seed", [0, 1])
def test_expert_teleoperator_solves_select_apple_on_the_sim_robot(seed):
    # The robot's cameras, image size and table differ from the expert's planning copy of the scene.
    sim = OmniDSim(small_robot(seed=seed, background="ood2"))
    expert = OmniDExpert(OmniDExpertConfig(task="select_apple", seed=seed))
    expert.connect()
    sim.connect()
    try:
        assert 0 < expert.plan_length < MAX_EPISODE_STEPS
        for _ in range(expert.plan_length + 5):
            sim.get_observation()
            sim.send_action(expert.get_action())
            if sim.is_success:
                break
        assert sim.is_success, f"seed {seed}: not solved after {sim.steps} steps"
        assert sim.task_description == "put the apple in the bowl"
    finally:
        sim.disconnect()
        expert.disconnect()


# --- calibration of the sim cameras ---------------------------------------------------------------
def test_calibration_file_of_the_sim_cameras(tmp_path):
    cameras = {
        "front": OmniDSimCameraConfig(source="cam_b", width=32, height=24),
        "cam_d": OmniDSimCameraConfig(width=32, height=24),
    }
    config = OmniDSimConfig(cameras=cameras, rig="bumped")
    path = export_sim_calibration(config, tmp_path / "rig.yaml")
    loaded = load_calibration_file(path)
    assert list(loaded) == ["observation.images.front", "observation.images.cam_d"]
    sim = OmniDSim(config)
    sim.connect()
    try:
        for name, cam in cameras.items():
            calib = loaded[f"observation.images.{name}"]
            assert calib == sim.camera_calibration(name)
            raw = sim._env.unwrapped.camera_calibration(cam.source)
            np.testing.assert_allclose(calib.K, raw["K"])
            np.testing.assert_allclose(calib.T_cam_world, raw["T_cam_world"])
            assert calib.image_size == (24, 32)
        moved = OmniDSim(OmniDSimConfig(cameras=cameras))  # the default rig
        moved.connect()
        try:
            default_pose = moved.camera_calibration("front").T_cam_world
            assert default_pose != loaded["observation.images.front"].T_cam_world
        finally:
            moved.disconnect()
        with pytest.raises(
            KeyError, match=r"camera: expected one of the robot's cameras \['front', 'cam_d'\]"
        ):
            sim.camera_calibration("cam_b")
    finally:
        sim.disconnect()


def test_sim_calibration_command_writes_the_file_and_refuses_other_robots(tmp_path, capsys):
    out = tmp_path / "rig.json"
    assert (
        sim_calibration_main(
            ["--robot.type=omnid_sim", "--robot.cameras={cam_c: {width: 16, height: 16}}", f"--output={out}"]
        )
        == 0
    )
    assert "Wrote the calibration of 1 camera(s) (cam_c) at 16x16 pixels" in capsys.readouterr().out
    assert list(json.loads(out.read_text())) == ["observation.images.cam_c"]
    importlib.import_module("lerobot.robots.so_follower")
    code = sim_calibration_main(["--robot.type=so101_follower", "--robot.port=/dev/null", f"--output={out}"])
    assert code == 2
    # so100 and so101 share one config class, whose type LeRobot reports as so100_follower.
    assert re.search(r"--robot.type: expected omnid_sim, got so10[01]_follower", capsys.readouterr().err)
