"""The wrist camera and the camera rigs: calibration checked against segmentation renders (the wrist
camera at several arm poses and along an expert episode, every rig's cameras), the per-frame calibration
observation, the size of the rigs' moves and the workspace seen by every camera of every rig."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator

import gym_omnid
import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gym_omnid.calibration import EXTRINSICS_OBS_PREFIX, INTRINSICS_OBS_PREFIX, invert_rigid, project
from gym_omnid.constants import HOME_JOINTS
from gym_omnid.env import OmniDEnv
from gym_omnid.experts import make_expert
from gym_omnid.rigs import RIG_PLACEMENTS
from gymnasium.utils.env_checker import check_env

HIDDEN_GROUP = 5  # geom group the render tests hide everything but the apple in
MIN_PROBE_PIXELS = 20  # a probe seen by fewer pixels gives no reliable centroid
MAX_ERROR_PX = 1.0
MAX_MEAN_ERROR_PX = 0.3  # a half-pixel convention slip shifts every probe by ~0.5 px
MOVED_RIGS = tuple(rig for rig in gym_omnid.RIGS if rig != gym_omnid.DEFAULT_RIG)
RIG_MOVE_M = (0.05, 0.20)  # each camera of a moved rig moves this far from its default placement...
RIG_TURN_DEG = (5.0, 20.0)  # ...and turns this much
GRID_STEPS = 9  # workspace grid points per axis
MIN_WORKSPACE_INSIDE = 0.85  # share of the workspace grid inside every image (default rig: 0.89-0.96)
IMAGE = 64  # px: side of the images of the projection checks
# Arm poses of the wrist camera check (rad): home, reaching left and low, reaching right, twisted.
ARM_POSES = (
    HOME_JOINTS,
    (0.5, 0.3, 1.7, 0.4, 1.1, 0.8),
    (-0.6, -0.2, 2.4, -0.5, 0.5, -1.2),
    (0.2, 0.8, 1.2, 1.0, -0.6, 2.0),
)
# Probe positions in the TCP frame (m; z along the approach, the camera on the TCP's -y side): between
# and beyond the fingers, up to 30 cm ahead.
TCP_OFFSETS = ((0.0, -0.02, 0.06), (0.04, -0.05, 0.1), (-0.06, -0.1, 0.2), (0.0, -0.15, 0.3))
PROBE_RADIUS = 0.02  # m: the apple shrunk for the arm-pose check (no physics runs there)
FIXED_PROBES = ((0.35, -0.25, 0.04), (0.55, 0.0, 0.04), (0.75, 0.25, 0.12), (0.6, -0.1, 0.3))  # world, m


def sphere_image_centre(K: np.ndarray, cam_T_world: np.ndarray, xyz_world: np.ndarray, radius: float):
    """Centre (u, v) of the ellipse a sphere projects to, for square pixels without skew.

    Off the optical axis a sphere's image is an ellipse whose major axis points at the principal point;
    its ends are the images of the two rays tangent to the sphere in the plane through the optical axis
    and the sphere's centre, and its centre (the centroid of the rendered pixels) is their midpoint, not
    the projection of the sphere's centre.
    """
    x, y, z = cam_T_world[:3, :3] @ xyz_world + cam_T_world[:3, 3]
    rho = math.hypot(x, y)
    theta = math.atan2(rho, z)
    alpha = math.asin(radius / math.sqrt(rho**2 + z**2))
    radial = (math.tan(theta + alpha) + math.tan(theta - alpha)) / 2
    direction = np.array([x, y]) / rho if rho > 0 else np.zeros(2)
    return K[:2, 2] + K[0, 0] * radial * direction


class ApplePicture:
    """Segmentation renders of the apple alone: every other geom is moved to a hidden group."""

    def __init__(self, env: OmniDEnv) -> None:
        self.env = env
        self.geom = env.model.geom("apple").id
        self.body = env.model.body("apple").id
        self.qpos_adr = env.model.jnt_qposadr[env.model.body_jntadr[self.body]]
        env.model.geom_group[:] = HIDDEN_GROUP
        env.model.geom_group[self.geom] = 0
        self.renderer = mujoco.Renderer(env.model, *env.image_size)
        self.renderer.enable_segmentation_rendering()

    def place(self, xyz_world: np.ndarray) -> None:
        """Move the apple (kinematics updated by the caller's ``mj_forward``)."""
        self.env.data.qpos[self.qpos_adr : self.qpos_adr + 3] = xyz_world

    def mask(self, cam: str) -> np.ndarray:
        """Boolean (H, W) mask of the apple's pixels in ``cam``, from the data as it is (no forward)."""
        option = mujoco.MjvOption()
        option.geomgroup[:] = 1
        option.geomgroup[HIDDEN_GROUP] = 0
        self.renderer.update_scene(self.env.data, camera=cam, scene_option=option)
        seg = self.renderer.render()  # H, W, 2: object id, object type
        return (seg[..., 0] == self.geom) & (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)

    def error_px(self, cam: str, calib: dict) -> float | None:
        """Distance from the calibration's image of the apple to its rendered centroid; None when the
        apple is not wholly in the image (cut by an edge or too small)."""
        mask = self.mask(cam)
        edges = np.concatenate([mask[0], mask[-1], mask[:, 0], mask[:, -1]])
        if mask.sum() < MIN_PROBE_PIXELS or edges.any():
            return None
        rows, cols = np.nonzero(mask)
        radius = float(self.env.model.geom_size[self.geom][0])
        centre = sphere_image_centre(calib["K"], calib["T_cam_world"], self.env.data.xpos[self.body], radius)
        return float(np.hypot(centre[0] - cols.mean(), centre[1] - rows.mean()))

    def close(self) -> None:
        self.renderer.close()


@pytest.fixture
def apple_picture(make_env) -> Iterator:
    """Factory ``apple_picture(**env_kwargs) -> ApplePicture`` on a reset select_apple env."""
    pictures: list[ApplePicture] = []

    def _make(**kwargs) -> ApplePicture:
        env = make_env("select_apple", **kwargs)
        env.reset(seed=0)
        pictures.append(ApplePicture(env))
        return pictures[-1]

    yield _make
    for picture in pictures:
        picture.close()


@pytest.fixture(scope="module")
def rig_calibrations() -> dict[str, dict[str, dict]]:
    """rig -> fixed camera -> calibration at IMAGE px."""
    calibs = {}
    for rig in gym_omnid.RIGS:
        env = gym.make("gym_omnid/select_apple", cameras=["cam_a"], image_size=IMAGE, rig=rig)
        calibs[rig] = {cam: env.unwrapped.camera_calibration(cam) for cam in gym_omnid.CAMERAS}
        env.close()
    return calibs


def _camera_centre(calib: dict) -> np.ndarray:
    return invert_rigid(calib["T_cam_world"])[:3, 3]


# --- the wrist camera ------------------------------------------------------------------------------
def test_wrist_camera_is_opt_in() -> None:
    assert gym_omnid.WRIST_CAMERA == "cam_wrist" and gym_omnid.WRIST_CAMERA not in gym_omnid.CAMERAS
    assert (*gym_omnid.CAMERAS, "cam_wrist") == gym_omnid.ALL_CAMERAS


@pytest.mark.parametrize("size", [128, (96, 160)])
def test_wrist_calibration_matches_renders_at_arm_poses(apple_picture, size) -> None:
    """At several arm poses, an apple between and ahead of the fingers lands where the wrist camera's
    calibration puts it."""
    picture = apple_picture(cameras=["cam_wrist"], image_size=size)
    env = picture.env
    env.model.geom_size[picture.geom][0] = env.model.geom_rbound[picture.geom] = PROBE_RADIUS
    errors = []
    centres = []
    for joints in ARM_POSES:
        env.data.qpos[env._arm_qpos] = joints
        mujoco.mj_forward(env.model, env.data)
        tcp_xyz, world_R_tcp = env.tcp_pose()
        calib = env.camera_calibration("cam_wrist")
        centres.append(_camera_centre(calib))
        for offset in TCP_OFFSETS:
            picture.place(tcp_xyz + world_R_tcp @ np.array(offset))
            mujoco.mj_forward(env.model, env.data)
            error = picture.error_px("cam_wrist", calib)
            assert error is not None, f"pose {joints}: apple at TCP offset {offset} not wholly in view"
            assert error < MAX_ERROR_PX, f"pose {joints}, TCP offset {offset}: {error:.2f} px"
            errors.append(error)
    assert np.mean(errors) < MAX_MEAN_ERROR_PX
    # The camera rides on the hand: each pose puts it somewhere else.
    assert min(np.linalg.norm(a - b) for a, b in itertools.combinations(centres, 2)) > 0.05


def test_wrist_calibration_in_every_step_matches_its_render(apple_picture) -> None:
    """Along an expert episode the observation's per-frame calibration is that of the frame just
    rendered: the apple, whenever wholly in view of the wrist camera, lands where it says."""
    picture = apple_picture(cameras=["cam_wrist", "cam_b"], image_size=128, per_frame_calibration=True)
    env = picture.env
    obs, _ = env.reset(seed=0)
    expert = make_expert(env)
    errors, extrinsics = [], []
    for _ in range(60):
        T_cam_world = obs[f"{EXTRINSICS_OBS_PREFIX}cam_wrist"].astype(np.float64).reshape(4, 4)
        K = obs[f"{INTRINSICS_OBS_PREFIX}cam_wrist"].astype(np.float64).reshape(3, 3)
        extrinsics.append(T_cam_world)
        np.testing.assert_array_equal(
            obs[f"{EXTRINSICS_OBS_PREFIX}cam_b"],
            env.camera_calibration("cam_b")["T_cam_world"].astype(np.float32).reshape(16),
        )
        error = picture.error_px("cam_wrist", {"K": K, "T_cam_world": T_cam_world})
        if error is not None:
            errors.append(error)
        obs, _, terminated, truncated, _ = env.step(expert.act())
        if terminated or truncated:
            break
    assert len(errors) >= 5, f"the apple was wholly in view in only {len(errors)} frames"
    assert max(errors) < MAX_ERROR_PX and np.mean(errors) < MAX_MEAN_ERROR_PX, errors
    moves = [np.abs(a - b).max() for a, b in itertools.pairwise(extrinsics)]
    assert sum(m > 1e-3 for m in moves) > len(moves) / 2  # the wrist camera moves in most steps


def test_per_frame_calibration_observation(make_env) -> None:
    env = make_env(
        "select_apple", cameras=["cam_c", "cam_wrist"], image_size=(48, 64), per_frame_calibration=True
    )
    obs, _ = env.reset(seed=1)
    obs, *_ = env.step(env.action_space.sample())
    assert obs in env.observation_space
    assert set(obs) == {
        "pixels",
        "agent_pos",
        *(
            f"{prefix}{cam}"
            for prefix in (EXTRINSICS_OBS_PREFIX, INTRINSICS_OBS_PREFIX)
            for cam in env.cameras
        ),
    }
    for cam in env.cameras:
        calib = env.camera_calibration(cam)
        extrinsics, intrinsics = obs[f"extrinsics.{cam}"], obs[f"intrinsics.{cam}"]
        assert extrinsics.dtype == intrinsics.dtype == np.float32
        assert extrinsics.shape == (16,) and intrinsics.shape == (9,)
        np.testing.assert_allclose(extrinsics.reshape(4, 4), calib["T_cam_world"], atol=1e-6)
        np.testing.assert_allclose(intrinsics.reshape(3, 3), calib["K"], rtol=1e-7)
        assert calib["image_size"] == (48, 64)
    # Off by default: the observation every existing dataset was recorded with.
    default = make_env("select_apple", cameras=["cam_c"], image_size=32)
    assert set(default.reset(seed=1)[0]) == {"pixels", "agent_pos"}


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")  # absolute poses in metres
@pytest.mark.filterwarnings("ignore:.*observation space m")  # calibration entries are unbounded
def test_check_env_with_wrist_camera_rig_and_calibration() -> None:
    env = gym.make(
        "gym_omnid/select_apple",
        cameras=["cam_wrist", "cam_d"],
        image_size=32,
        rig="higher",
        per_frame_calibration=True,
    )
    try:
        check_env(env.unwrapped, skip_render_check=False)
    finally:
        env.close()


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"rig": "lab9"}, "rig: expected one of ['default', 'closer', 'higher', 'bumped'], got 'lab9'"),
        ({"per_frame_calibration": "yes"}, "per_frame_calibration: expected True or False, got 'yes'"),
        ({"cameras": ["cam_wrist", "cam_x"]}, "cameras: expected a non-empty subset of"),
    ],
)
def test_bad_rig_and_calibration_kwargs(kwargs: dict, expected: str) -> None:
    with pytest.raises(ValueError) as err:
        OmniDEnv("select_apple", image_size=32, **kwargs)
    assert expected in str(err.value)


# --- the rigs --------------------------------------------------------------------------------------
def test_rig_names_and_placements() -> None:
    assert tuple(RIG_PLACEMENTS) == gym_omnid.RIGS and gym_omnid.RIGS[0] == gym_omnid.DEFAULT_RIG
    for rig, placements in RIG_PLACEMENTS.items():
        assert tuple(placements) == gym_omnid.CAMERAS, rig


def test_rigs_move_and_turn_every_camera(rig_calibrations) -> None:
    default = rig_calibrations[gym_omnid.DEFAULT_RIG]
    for rig, cam in itertools.product(MOVED_RIGS, gym_omnid.CAMERAS):
        calib = rig_calibrations[rig][cam]
        move = np.linalg.norm(_camera_centre(calib) - _camera_centre(default[cam]))
        R_delta = calib["T_cam_world"][:3, :3] @ default[cam]["T_cam_world"][:3, :3].T
        turn = math.degrees(math.acos(np.clip((np.trace(R_delta) - 1) / 2, -1.0, 1.0)))
        assert RIG_MOVE_M[0] <= move <= RIG_MOVE_M[1], (rig, cam, move)
        assert RIG_TURN_DEG[0] <= turn <= RIG_TURN_DEG[1], (rig, cam, turn)


def test_workspace_projects_into_every_camera_of_every_rig(rig_calibrations) -> None:
    """The workspace volume lies in front of every camera, at least 85 % of a grid over it inside the
    image, its centre in the central half of the image."""
    bounds = np.array(gym_omnid.WORKSPACE_BOUNDS)
    axes = [np.linspace(lo, hi, GRID_STEPS) for lo, hi in bounds]
    xyz_world = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    for rig, cam in itertools.product(gym_omnid.RIGS, gym_omnid.CAMERAS):
        calib = rig_calibrations[rig][cam]
        uv_pix, depth = project(calib["K"], calib["T_cam_world"], xyz_world)
        assert (depth > 0).all(), (rig, cam)
        inside = np.all((uv_pix >= -0.5) & (uv_pix <= IMAGE - 0.5), axis=1).mean()
        assert inside >= MIN_WORKSPACE_INSIDE, (rig, cam, inside)
        centre_uv, _ = project(calib["K"], calib["T_cam_world"], bounds.mean(axis=1))
        assert (np.abs(centre_uv[0] - (IMAGE - 1) / 2) <= IMAGE / 4).all(), (rig, cam, centre_uv)


@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_task_objects_project_into_every_rig(make_env, rig_calibrations, task: str) -> None:
    """Every key object, in the ID and position-OOD layouts, is in every image of every rig."""
    for layout in ("id", "position_ood"):
        env = make_env(task, cameras=["cam_a"], image_size=IMAGE, layout=layout)
        for seed in range(3):
            env.reset(seed=seed)
            xyz_world = np.array(list(env.object_positions().values()))
            for rig, cam in itertools.product(MOVED_RIGS, gym_omnid.CAMERAS):
                calib = rig_calibrations[rig][cam]
                uv_pix, depth = project(calib["K"], calib["T_cam_world"], xyz_world)
                assert (depth > 0).all() and ((uv_pix >= 0) & (uv_pix <= IMAGE - 1)).all(), (
                    layout,
                    seed,
                    rig,
                    cam,
                    uv_pix,
                )


@pytest.mark.parametrize("rig", MOVED_RIGS)
def test_rig_calibration_matches_rendered_pixels(apple_picture, rig: str) -> None:
    picture = apple_picture(image_size=(96, 128), rig=rig)
    env = picture.env
    errors = []
    for xyz_world in FIXED_PROBES:
        picture.place(np.array(xyz_world))
        mujoco.mj_forward(env.model, env.data)
        for cam in gym_omnid.CAMERAS:
            error = picture.error_px(cam, env.camera_calibration(cam))
            assert error is not None and error < MAX_ERROR_PX, (cam, xyz_world, error)
            errors.append(error)
    assert np.mean(errors) < MAX_MEAN_ERROR_PX


def test_rig_changes_the_images_only(make_env) -> None:
    default = make_env("select_apple", cameras=["cam_b"], image_size=32)
    bumped = make_env("select_apple", cameras=["cam_b"], image_size=32, rig="bumped")
    obs_default, _ = default.reset(seed=2)
    obs_bumped, _ = bumped.reset(seed=2)
    np.testing.assert_array_equal(obs_default["agent_pos"], obs_bumped["agent_pos"])
    assert np.abs(obs_default["pixels"]["cam_b"].astype(int) - obs_bumped["pixels"]["cam_b"]).mean() > 5
