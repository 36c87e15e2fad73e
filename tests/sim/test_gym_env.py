"""OmniDEnv API: registration, check_env, spaces, determinism, variants and input validation."""

from __future__ import annotations

import importlib
import itertools

import gym_omnid
import gymnasium as gym
import numpy as np
import pytest
from gym_omnid.constants import (
    ENV_STATE_OBS_KEY,
    FINGER_TRAVEL,
    ID_HALF_EXTENT,
    POSITION_BANDS,
    TASK_ONEHOT_NAMES,
)
from gym_omnid.env import OmniDEnv
from gym_omnid.experts import waypoint_action
from gym_omnid.tasks import task_onehot
from gym_omnid.tasks.base import offset_band, sample_layout
from gymnasium.utils.env_checker import check_env

REGISTERED = sorted(env_id for env_id in gym.registry if env_id.startswith("gym_omnid/"))
SETTLE_TOL = 3e-3  # m: how far a free object may move while settling at reset
TASK_MODULES = {task: importlib.import_module(f"gym_omnid.tasks.{task}") for task in gym_omnid.TASKS}
NOMINAL = {task: {p.name: p for p in module.PLACEMENTS} for task, module in TASK_MODULES.items()}
OOD_LAYOUTS = tuple(layout for layout in gym_omnid.LAYOUTS if layout != "id")
# texas_holdem's cards in the two farthest graded bands reach y 0.43 m, up to 3.1 cm past the workspace
# (the graded bands are the benchmark's for select_apple, whose objects stay inside).
BEYOND_WORKSPACE = {("texas_holdem", "position_band_3"), ("texas_holdem", "position_band_4")}
BEYOND_WORKSPACE_MARGIN = 0.04  # m


def test_exports() -> None:
    assert gym_omnid.CAMERAS == ("cam_a", "cam_b", "cam_c", "cam_d", "cam_e")
    assert gym_omnid.TRAIN_CAMERAS == ("cam_b", "cam_c", "cam_d", "cam_e")
    assert gym_omnid.LAYOUTS == (
        "id",
        "position_ood",
        "position_band_1",
        "position_band_2",
        "position_band_3",
        "position_band_4",
    )
    assert gym_omnid.BACKGROUNDS == ("id", "ood1", "ood2", "ood3", "ood4")
    assert gym_omnid.CONTROL_FPS == 10
    assert gym_omnid.WORKSPACE_BOUNDS == ((0.2, 0.84), (-0.4, 0.4), (0.0, 0.32))
    assert [f"gym_omnid/{task}" for task in sorted(gym_omnid.TASKS)] == REGISTERED


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")  # absolute poses in metres
@pytest.mark.parametrize("env_id", REGISTERED)
def test_registration_and_check_env(env_id: str) -> None:
    spec = gym.spec(env_id)
    assert spec.entry_point == "gym_omnid.env:OmniDEnv"
    assert spec.max_episode_steps == gym_omnid.MAX_EPISODE_STEPS
    env = gym.make(env_id, image_size=64)
    try:
        assert isinstance(env.unwrapped, OmniDEnv)
        assert env.metadata["render_fps"] == gym_omnid.CONTROL_FPS
        check_env(env.unwrapped, skip_render_check=False)
    finally:
        env.close()


@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_reset_and_step_contract(make_env, task: str) -> None:
    env = make_env(task)
    obs, info = env.reset(seed=3)
    assert info == {"is_success": False}
    assert obs in env.observation_space
    assert env.state_names == list(gym_omnid.STATE_NAMES) and len(env.state_names) == gym_omnid.STATE_DIM
    assert env.action_names == list(gym_omnid.ACTION_NAMES) and len(env.action_names) == gym_omnid.ACTION_DIM
    assert obs["agent_pos"].dtype == np.float32
    assert obs["agent_pos"][9] == pytest.approx(0.0, abs=0.02)  # gripper open
    assert isinstance(env.task_description, str) and len(env.task_description.split()) >= 4
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert set(info) == {"is_success"} and isinstance(info["is_success"], bool)
    assert reward == float(info["is_success"]) and terminated == info["is_success"] and not truncated
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == (256, 384, 3)
    for name, xyz in env.object_positions().items():
        assert xyz.shape == (3,), name


def test_tube_description_names_the_target(make_env) -> None:
    env = make_env("select_chemistry_tube", cameras=["cam_a"], image_size=32)
    colours = set()
    for seed in range(12):
        env.reset(seed=seed)
        colour = env.task_spec.target
        colours.add(colour)
        assert env.task_description == f"put the {colour} tube in the holder"
        np.testing.assert_allclose(
            env.object_positions()["target_tube"], env.object_positions()[f"tube_{colour}"]
        )
    assert len(colours) >= 3


@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_same_seed_same_observations(make_env, task: str) -> None:
    env_a, env_b = make_env(task), make_env(task)
    action = waypoint_action(np.array([0.5, 0.1, 0.2]), 0.3, 0.5)
    obs_a, _ = env_a.reset(seed=7)
    obs_b, _ = env_b.reset(seed=7)
    for _ in range(3):
        obs_a, *_ = env_a.step(action)
        obs_b, *_ = env_b.step(action)
    for cam in gym_omnid.CAMERAS:
        np.testing.assert_array_equal(obs_a["pixels"][cam], obs_b["pixels"][cam])
    np.testing.assert_array_equal(obs_a["agent_pos"], obs_b["agent_pos"])
    # Re-seeding the same env reproduces its first observation; another seed moves the objects.
    first, _ = env_a.reset(seed=11)
    again, _ = env_a.reset(seed=11)
    np.testing.assert_array_equal(first["pixels"]["cam_b"], again["pixels"]["cam_b"])
    positions = env_a.object_positions()
    env_a.reset(seed=12)
    assert any(np.linalg.norm(positions[k] - v) > 1e-3 for k, v in env_a.object_positions().items())


def _offsets(env: OmniDEnv, task: str) -> dict[str, np.ndarray]:
    """Planar offsets of the key objects from their nominal positions after reset."""
    positions = env.object_positions()
    return {
        name: positions[name][:2] - np.asarray(p.nominal_xy) for name, p in NOMINAL[task].items() if p.key
    }


@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_layout_variants(make_env, task: str) -> None:
    """ID key objects stay in the 10 cm square; position-OOD ones in the band out to the 20 cm square, those
    of a graded band at their distance outside the square, after the objects settled."""
    env_id = make_env(task, cameras=["cam_a"], image_size=32)
    envs_ood = [make_env(task, cameras=["cam_a"], image_size=32, layout=layout) for layout in OOD_LAYOUTS]
    for seed in range(15):
        env_id.reset(seed=seed)
        for name, offset in _offsets(env_id, task).items():
            assert np.abs(offset).max() <= ID_HALF_EXTENT + SETTLE_TOL, (seed, name)
        for env in envs_ood:
            env.reset(seed=seed)
            inner, outer = offset_band(env.layout)
            for name, offset in _offsets(env, task).items():
                linf = np.abs(offset).max()
                assert inner - SETTLE_TOL < linf <= outer + SETTLE_TOL, (env.layout, seed, name, linf)


def test_position_bands_tile_the_position_ood_band_and_beyond() -> None:
    """Graded bands 2.5 cm wide, from the ID square outwards; the first two make up ``position_ood``."""
    bands = [offset_band(layout) for layout in POSITION_BANDS]
    assert bands[0][0] == ID_HALF_EXTENT and bands[1][1] == offset_band("position_ood")[1]
    for (_, outer), (inner, _) in itertools.pairwise(bands):
        assert inner == outer
    assert [round(outer - inner, 6) for inner, outer in bands] == [0.025] * 4
    with pytest.raises(ValueError, match="layout: expected position_ood or one of"):
        offset_band("position_band_9")


@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_layout_sampler_exact_bands_and_keepout(task: str) -> None:
    module = TASK_MODULES[task]
    rng = np.random.default_rng(0)
    for layout in gym_omnid.LAYOUTS:
        inner, outer = (0.0, ID_HALF_EXTENT) if layout == "id" else offset_band(layout)
        for _ in range(200):
            xy = sample_layout(rng, module.PLACEMENTS, layout)
            for i, a in enumerate(module.PLACEMENTS):
                linf = np.abs(xy[a.name] - a.nominal_xy).max()
                if not a.key:
                    assert linf <= ID_HALF_EXTENT
                else:
                    assert inner <= linf <= outer and (layout == "id" or linf > inner), (layout, a.name)
                for b in module.PLACEMENTS[i + 1 :]:
                    assert np.linalg.norm(xy[a.name] - xy[b.name]) >= a.keepout + b.keepout


@pytest.mark.parametrize("layout", gym_omnid.LAYOUTS)
@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_object_positions_lie_in_the_workspace_bounds(make_env, task: str, layout: str) -> None:
    """Every object of every task and layout lies inside ``WORKSPACE_BOUNDS`` (the policy's volume), but for
    ``BEYOND_WORKSPACE``, within a few cm of it."""
    low, high = np.array(gym_omnid.WORKSPACE_BOUNDS).T  # 3, 2 -> (3,), (3,)
    if (task, layout) in BEYOND_WORKSPACE:
        low, high = low - BEYOND_WORKSPACE_MARGIN, high + BEYOND_WORKSPACE_MARGIN
    env = make_env(task, cameras=["cam_a"], image_size=32, layout=layout)
    for seed in range(6):
        env.reset(seed=seed)
        for name, xyz in env.object_positions().items():
            assert np.all((low <= xyz) & (xyz <= high)), (seed, name, xyz)


@pytest.mark.parametrize("layout", gym_omnid.LAYOUTS)
def test_reset_objects_do_not_touch_each_other(make_env, layout: str) -> None:
    env = make_env("select_apple", cameras=["cam_a"], image_size=32, layout=layout)
    fruit_and_bowl = {env.model.body(name).id for name in ("apple", "bowl", "orange", "lemon", "banana")}
    for seed in range(10):
        env.reset(seed=seed)
        bodies = env.model.geom_bodyid[env.data.contact.geom[: env.data.ncon]]
        for body_a, body_b in bodies:
            assert not (body_a in fruit_and_bowl and body_b in fruit_and_bowl and body_a != body_b), seed
        for name in ("apple", "orange"):
            assert env.data.xpos[env.model.body(name).id][2] > 0.03  # resting on the table, not sunk


@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_backgrounds_differ_in_pixels(make_env, task: str) -> None:
    images = {}
    for background in gym_omnid.BACKGROUNDS:
        env = make_env(task, cameras=["cam_a"], background=background, image_size=64)
        obs, _ = env.reset(seed=0)
        images[background] = obs["pixels"]["cam_a"].astype(np.int16)
    for i, a in enumerate(gym_omnid.BACKGROUNDS):
        for b in gym_omnid.BACKGROUNDS[i + 1 :]:
            assert np.abs(images[a] - images[b]).mean() > 10, (a, b)


def test_set_background_reuploads_without_recompiling(make_env) -> None:
    env = make_env("select_apple", cameras=["cam_b"])
    obs, _ = env.reset(seed=0)
    model = env.model
    env.set_background("ood4")
    assert env.model is model and env.background == "ood4"
    obs_ood, _ = env.reset(seed=0)
    assert np.abs(obs_ood["pixels"]["cam_b"].astype(np.int16) - obs["pixels"]["cam_b"]).mean() > 10
    reference = make_env("select_apple", cameras=["cam_b"], background="ood4")
    obs_ref, _ = reference.reset(seed=0)
    np.testing.assert_array_equal(obs_ood["pixels"]["cam_b"], obs_ref["pixels"]["cam_b"])


def test_blackout_cameras_observe_black_images(make_env) -> None:
    """The blacked-out cameras' observed pixels are zero; the rest of the observation, the episode and the
    rendered video are those of the same env without blackout."""
    cameras = ["cam_b", "cam_c"]
    env = make_env("select_apple", cameras=cameras, image_size=32, blackout_cameras=["cam_c"])
    reference = make_env("select_apple", cameras=cameras, image_size=32)
    action = waypoint_action(np.array([0.5, 0.1, 0.2]), 0.3, 0.5)
    for obs, ref in (
        (env.reset(seed=0)[0], reference.reset(seed=0)[0]),
        (env.step(action)[0], reference.step(action)[0]),
    ):
        assert obs in env.observation_space
        assert obs["pixels"]["cam_c"].shape == (32, 32, 3) and not obs["pixels"]["cam_c"].any()
        assert ref["pixels"]["cam_c"].any()
        np.testing.assert_array_equal(obs["pixels"]["cam_b"], ref["pixels"]["cam_b"])
        np.testing.assert_array_equal(obs["agent_pos"], ref["agent_pos"])
    np.testing.assert_array_equal(env.render(), reference.render())
    assert make_env("select_apple", cameras=["cam_b"], image_size=32).blackout_cameras == ()
    for bad in (["cam_a"], ["cam_b", "cam_b"]):
        with pytest.raises(
            ValueError, match=r"blackout_cameras: expected distinct cameras among the observed"
        ):
            make_env("select_apple", cameras=["cam_b"], image_size=32, blackout_cameras=bad)


@pytest.mark.parametrize("cameras", [["cam_a"], ["cam_e", "cam_b"], list(gym_omnid.TRAIN_CAMERAS)])
def test_camera_subsets(make_env, cameras: list[str]) -> None:
    env = make_env("select_chemistry_tube", cameras=cameras, image_size=48)
    obs, _ = env.reset(seed=0)
    assert list(obs["pixels"]) == cameras
    assert list(env.observation_space["pixels"].spaces) == cameras


@pytest.mark.parametrize(("size", "shape"), [(64, (64, 64)), ((96, 160), (96, 160)), (480, (480, 480))])
def test_image_size(make_env, size, shape) -> None:
    env = make_env("select_apple", cameras=["cam_c"], image_size=size)
    obs, _ = env.reset(seed=0)
    assert obs["pixels"]["cam_c"].shape == (*shape, 3) and obs["pixels"]["cam_c"].dtype == np.uint8
    assert env.observation_space["pixels"]["cam_c"].shape == (*shape, 3)
    assert obs["pixels"]["cam_c"].std() > 5  # a real picture, not a blank buffer
    assert env.camera_calibration("cam_c")["image_size"] == shape


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"task": "select_banana"}, "task"),
        ({"cameras": ["cam_a", "cam_x"]}, "cameras"),
        ({"cameras": []}, "cameras"),
        ({"cameras": ["cam_a", "cam_a"]}, "cameras"),
        ({"layout": "ood"}, "layout"),
        ({"background": "ood5"}, "background"),
        ({"image_size": 0}, "image_size"),
        ({"image_size": (64, 64, 3)}, "image_size"),
        ({"image_size": 64.0}, "image_size"),
        ({"render_mode": "human"}, "render_mode"),
        ({"task_onehot": "yes"}, "task_onehot"),
    ],
)
def test_bad_kwargs_raise_value_error_naming_the_field(kwargs: dict, field: str) -> None:
    kwargs = {"task": "select_apple", **kwargs}
    bad = next(iter(v for k, v in kwargs.items() if k == field))
    with pytest.raises(ValueError, match=rf"^{field}: expected .* got ") as err:
        OmniDEnv(**kwargs)
    assert repr(bad) in str(err.value) or str(bad) in str(err.value)


def test_task_onehot_helper() -> None:
    assert TASK_ONEHOT_NAMES == gym_omnid.TASKS
    onehots = np.stack([task_onehot(task) for task in gym_omnid.TASKS])
    assert onehots.dtype == np.float32
    np.testing.assert_array_equal(onehots, np.eye(len(gym_omnid.TASKS)))
    with pytest.raises(ValueError, match=r"^task: expected one of .* got 'make_tea'"):
        task_onehot("make_tea")


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")  # absolute poses in metres
@pytest.mark.parametrize("task", ["select_apple", "texas_holdem"])
def test_task_onehot_observation(make_env, task: str) -> None:
    env = make_env(task, cameras=["cam_b"], image_size=32, task_onehot=True)
    expected = np.eye(len(gym_omnid.TASKS), dtype=np.float32)[gym_omnid.TASKS.index(task)]
    obs, _ = env.reset(seed=0)
    for _ in range(2):  # the observation of reset, then of a step
        assert obs in env.observation_space
        assert obs[ENV_STATE_OBS_KEY].dtype == np.float32
        np.testing.assert_array_equal(obs[ENV_STATE_OBS_KEY], expected)
        obs, *_ = env.step(env.action_space.sample())
    space = env.observation_space[ENV_STATE_OBS_KEY]
    assert space.shape == (len(gym_omnid.TASKS),) and (space.low == 0).all() and (space.high == 1).all()
    check_env(env)
    # Off by default: the observation every existing dataset was recorded with.
    assert ENV_STATE_OBS_KEY not in make_env(task, cameras=["cam_b"], image_size=32).reset(seed=0)[0]


def test_bad_action_shape(make_env) -> None:
    env = make_env("select_apple", cameras=["cam_a"], image_size=32)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(np.zeros(3, dtype=np.float32))


def test_gripper_state_follows_command(make_env) -> None:
    env = make_env("select_apple", cameras=["cam_a"], image_size=32)
    env.reset(seed=0)
    action = waypoint_action(np.array([0.4, 0.0, 0.3]), 0.0, 1.0)
    for _ in range(5):
        obs, *_ = env.step(action)
    assert obs["agent_pos"][9] == pytest.approx(1.0, abs=0.05)
    finger = env.model.joint("finger_left").id
    assert env.data.qpos[env.model.jnt_qposadr[finger]] < 0.1 * FINGER_TRAVEL


@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_random_actions_stay_physical(make_env, task: str) -> None:
    """Random targets (hand slammed into the table and objects) keep the state finite, inside the
    observation space, and raise no MuJoCo warnings (instability, constraint overflow)."""
    env = make_env(task, cameras=["cam_a"], image_size=32)
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(80):
        obs, *_ = env.step(env.action_space.sample())
        assert obs in env.observation_space, obs["agent_pos"]
    assert all(warning.number == 0 for warning in env.data.warning)
