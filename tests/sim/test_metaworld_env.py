"""The MetaWorld suite (``gym_omnid.metaworld_suite``): registration, the MuJoCo 4 weld fix, observation
format, seeded layouts, cheap rendering and MetaWorld's scripted experts through our wrapper."""

from __future__ import annotations

import json
from collections.abc import Iterator

import gymnasium as gym
import mujoco
import numpy as np
import pytest

pytest.importorskip("metaworld")

import gym_omnid.metaworld_suite as suite
from gym_omnid.calibration import EXTRINSICS_OBS_PREFIX, INTRINSICS_OBS_PREFIX, invert_rigid
from gym_omnid.metaworld_suite.env import MOCAP_WELD_DATA, MetaWorldEnv, make_metaworld_env
from gym_omnid.metaworld_suite.experts import make_expert, run_expert_episode
from gymnasium.utils.env_checker import check_env
from metaworld.env_dict import ALL_V3_ENVIRONMENTS
from metaworld.policies import ENV_POLICY_MAP

from lerobot_omnid.benchmark import metaworld_comparison

SIZE = 32  # px: small images keep these tests fast
EXPERT_TASKS = ("push-v3", "assembly-v3")
EXPERT_SEEDS = (0, 1, 2)
LAYOUT_SEEDS = (0, 1, 2, 3)
MUJOCO_MAJOR = int(mujoco.__version__.split(".")[0])


@pytest.fixture
def make_env() -> Iterator:
    """Factory ``make_env(task, **kwargs) -> MetaWorldEnv`` (unwrapped) that closes every env it made."""
    envs: list[gym.Env] = []

    def _make(task: str = "push-v3", **kwargs) -> MetaWorldEnv:
        envs.append(gym.make(f"{suite.GYM_NAMESPACE}/{task}", **{"image_size": SIZE, **kwargs}))
        return envs[-1].unwrapped

    yield _make
    for env in envs:
        env.close()


def _layout(env: MetaWorldEnv) -> np.ndarray:
    """Object poses and goal of the current episode: MetaWorld's flat observation without the hand."""
    obs = env.metaworld_observation()
    return np.concatenate([obs[4:18], obs[-3:]])


def test_task_list_matches_metaworld() -> None:
    assert set(suite.TASKS) == set(ALL_V3_ENVIRONMENTS) <= set(ENV_POLICY_MAP)
    registered = sorted(i for i in gym.registry if i.startswith(f"{suite.GYM_NAMESPACE}/"))
    assert registered == sorted(f"{suite.GYM_NAMESPACE}/{task}" for task in suite.TASKS)
    spec = gym.spec(f"{suite.GYM_NAMESPACE}/assembly-v3")
    assert spec.entry_point == "gym_omnid.metaworld_suite.env:MetaWorldEnv"
    assert spec.max_episode_steps == suite.MAX_EPISODE_STEPS


@pytest.mark.skipif(MUJOCO_MAJOR < 4, reason="the weld rows grew to 12 entries in MuJoCo 4")
def test_metaworld_alone_fails_on_mujoco_4_and_our_welds_keep_the_compiled_tail(make_env) -> None:
    with pytest.raises(ValueError, match="could not broadcast input array from shape \\(11,\\)"):
        ALL_V3_ENVIRONMENTS["push-v3"]()
    env = make_env()
    compiled = mujoco.MjModel.from_xml_path(env._mw.model_name)
    welds = np.flatnonzero(env.model.eq_type == mujoco.mjtEq.mjEQ_WELD)
    assert len(welds) == 1
    np.testing.assert_array_equal(env.model.eq_data[welds[0], : len(MOCAP_WELD_DATA)], MOCAP_WELD_DATA)
    np.testing.assert_array_equal(
        env.model.eq_data[welds[0], len(MOCAP_WELD_DATA) :],
        compiled.eq_data[welds[0], len(MOCAP_WELD_DATA) :],
    )


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")
@pytest.mark.filterwarnings("ignore:.*observation space m")  # calibration entries are unbounded
def test_check_env_with_every_camera_and_calibration(make_env) -> None:
    env = make_env("assembly-v3", cameras=list(suite.ALL_CAMERAS), per_frame_calibration=True)
    check_env(env, skip_render_check=False)


def test_observation_format(make_env) -> None:
    env = make_env("pick-place-wall-v3", per_frame_calibration=True, image_size=(24, 40))
    assert env.cameras == suite.DEFAULT_CAMERAS == ("corner", "corner2", "corner3", "behindGripper")
    assert env.metadata["render_fps"] == suite.CONTROL_FPS
    assert env._mw.dt == pytest.approx(1.0 / suite.CONTROL_FPS)
    obs, info = env.reset(seed=0)
    assert info == {"is_success": False}
    obs, reward, terminated, truncated, info = env.step(np.zeros(suite.ACTION_DIM, np.float32))
    assert obs in env.observation_space and set(info) == {"is_success"}
    assert isinstance(reward, float) and not terminated and not truncated
    assert env.state_names == list(suite.STATE_NAMES) and env.action_names == list(suite.ACTION_NAMES)
    np.testing.assert_allclose(obs["agent_pos"], env.metaworld_observation()[:4], atol=1e-6)
    for cam in env.cameras:
        assert obs["pixels"][cam].shape == (24, 40, 3) and obs["pixels"][cam].dtype == np.uint8
        calib = env.camera_calibration(cam)
        assert calib["image_size"] == (24, 40)
        np.testing.assert_allclose(
            obs[f"{EXTRINSICS_OBS_PREFIX}{cam}"].reshape(4, 4), calib["T_cam_world"], atol=1e-6
        )
        np.testing.assert_allclose(obs[f"{INTRINSICS_OBS_PREFIX}{cam}"].reshape(3, 3), calib["K"], rtol=1e-7)
    assert env.render().shape == (2 * 24, 2 * 40, 3)
    assert env.task_description == "pick place wall"


def test_fixed_cameras_upright_and_static_hand_camera_moves(make_env) -> None:
    """The corner cameras are turned upright (world up points up in their images); they never move, the
    hand camera does."""
    env = make_env("push-v3", cameras=list(suite.ALL_CAMERAS))
    env.reset(seed=0)
    before = {cam: env.camera_calibration(cam)["T_cam_world"] for cam in suite.ALL_CAMERAS}
    for cam in suite.FIXED_CAMERAS:
        world_R_cam = invert_rigid(before[cam])[:3, :3]
        assert world_R_cam[2, 1] < 0, cam  # the OpenCV camera's y (image down) points down in the world
    for _ in range(10):
        env.step(np.array([1.0, 0.0, 1.0, 0.0], np.float32))
    for cam in suite.ALL_CAMERAS:
        moved = np.abs(env.camera_calibration(cam)["T_cam_world"] - before[cam]).max()
        assert (moved > 1e-3) == (cam in suite.HAND_CAMERAS), (cam, moved)


def test_rendering_is_cheap(make_env) -> None:
    env = make_env("push-v3", image_size=(24, 40))
    quality = env.model.vis.quality
    assert (quality.shadowsize, quality.offsamples) == (0, 0)
    assert (env.model.vis.global_.offwidth, env.model.vis.global_.offheight) == (40, 24)


@pytest.mark.parametrize("task", ["push-v3", "assembly-v3"])
def test_same_seed_same_layout_different_seeds_different_layouts(make_env, task: str) -> None:
    """Seed s gives one layout, in any order and in any env instance; different seeds differ."""
    env, other = make_env(task, cameras=["corner"]), make_env(task, cameras=["corner"])
    layouts = {}
    for seed in LAYOUT_SEEDS:
        env.reset(seed=seed)
        layouts[seed] = _layout(env)
        env.step(env.action_space.sample())
    for seed in reversed(LAYOUT_SEEDS):
        obs, _ = other.reset(seed=seed)
        np.testing.assert_array_equal(_layout(other), layouts[seed])
    env.reset(seed=LAYOUT_SEEDS[0])
    first, _ = env.reset(seed=LAYOUT_SEEDS[0])
    np.testing.assert_array_equal(first["pixels"]["corner"], obs["pixels"]["corner"])  # seed 0 both times
    distinct = {tuple(np.round(layout, 6)) for layout in layouts.values()}
    assert len(distinct) == len(LAYOUT_SEEDS)


@pytest.mark.parametrize("task", EXPERT_TASKS)
def test_expert_succeeds_through_the_wrapper(make_env, task: str) -> None:
    env = make_env(task, cameras=["corner"])
    for seed in EXPERT_SEEDS:
        success, steps = run_expert_episode(env, seed, suite.MAX_EPISODE_STEPS)
        assert success, (task, seed, steps)
    expert = make_expert(env)
    action = expert.act()
    assert action.shape == (suite.ACTION_DIM,) and action.dtype == np.float32
    assert np.all(np.abs(action) <= 1.0)


def test_blackout_cameras_are_black_and_the_others_and_the_calibration_unchanged(make_env) -> None:
    seen = make_env(per_frame_calibration=True)
    blind = make_env(per_frame_calibration=True, blackout_cameras=["corner", "behindGripper"])
    obs_seen, _ = seen.reset(seed=5)
    obs_blind, _ = blind.reset(seed=5)
    for cam in suite.DEFAULT_CAMERAS:
        if cam in ("corner", "behindGripper"):
            assert not obs_blind["pixels"][cam].any()
        else:
            assert np.array_equal(obs_blind["pixels"][cam], obs_seen["pixels"][cam])
        assert np.array_equal(obs_blind[f"extrinsics.{cam}"], obs_seen[f"extrinsics.{cam}"])
    assert obs_seen["pixels"]["corner"].any()


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"task": "make-tea-v3"}, "task: expected one of ['assembly-v3'"),
        ({"cameras": ["corner", "cam_b"]}, "cameras: expected a non-empty subset of ['corner'"),
        ({"image_size": 0}, "image_size: expected an int or (height, width)"),
        ({"per_frame_calibration": "yes"}, "per_frame_calibration: expected True or False, got 'yes'"),
        (
            {"blackout_cameras": ["gripperPOV"]},
            "blackout_cameras: expected distinct cameras among the observed",
        ),
    ],
)
def test_bad_kwargs_are_named(kwargs: dict, expected: str) -> None:
    with pytest.raises(ValueError) as err:
        MetaWorldEnv(**{"task": "push-v3", **kwargs})
    assert expected in str(err.value)


def test_the_comparisons_volume_holds_every_hand_object_and_goal_of_the_experts_episodes() -> None:
    """OmniD's volume in the MetaWorld comparison is this suite's workspace: the hand, both objects and the
    goal stay inside it through the scripted experts' episodes of the compared tasks (MetaWorld's flat
    observation, layouts of the demonstrations' env seeds and of the first test seeds of each range)."""
    low, high = np.array(json.loads(metaworld_comparison.VOLUME_BOUNDS)).T
    for task in metaworld_comparison.PUBLISHED:
        env, expert = make_metaworld_env(task), ENV_POLICY_MAP[task]()
        for seed in (*range(3), *(first + k for first in metaworld_comparison.TEST_SEEDS for k in range(2))):
            env.seed(seed)
            obs, _ = env.reset()
            for _ in range(metaworld_comparison.EPISODE_LENGTH):
                # hand, first object, second object (zero where the task has none), goal
                for point in (obs[0:3], obs[4:7], obs[11:14], obs[-3:]):
                    if point.any():
                        assert np.all((low <= point) & (point <= high)), (task, seed, point.round(3))
                obs, _, _, _, info = env.step(expert.get_action(obs))
                if info["success"]:
                    break
        env.close()
