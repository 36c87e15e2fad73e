"""MetaWorldEnv: one MetaWorld v3 task seen by several calibrated cameras, in ``gym_omnid``'s format."""

from __future__ import annotations

import atexit
import weakref
from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from gym_omnid.calibration import calibration_observation, mujoco_camera_calibration
from gym_omnid.metaworld_suite.constants import (
    ACTION_DIM,
    ACTION_NAMES,
    ALL_CAMERAS,
    CONTROL_FPS,
    DEFAULT_CAMERAS,
    DEFAULT_IMAGE_SIZE,
    FIXED_CAMERAS,
    MAX_IMAGE_SIDE,
    RENDER_MOSAIC_COLUMNS,
    STATE_DIM,
    STATE_HIGH,
    STATE_LOW,
    STATE_NAMES,
    TASKS,
)

RENDER_MODES = ("rgb_array",)
# MetaWorld's weld data for its mocap weld: anchor (3), relative position (3), relative orientation
# quaternion (4, identity), torque scale (1).
MOCAP_WELD_DATA = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 5.0)
TURN_HALF = np.array([0.0, 0.0, 0.0, 1.0])  # quaternion: 180 degrees about a camera's optical (z) axis
UNBOUNDED_STEPS = 2**62  # MetaWorld's own horizon, lifted: gymnasium's TimeLimit ends episodes instead


class _Mujoco4Welds:
    """Mixin fixing MetaWorld 3.0.0's ``reset_mocap_welds`` for MuJoCo >= 4.

    MetaWorld assigns its 11 weld values to whole ``eq_data`` rows; MuJoCo 4 made those rows 12 long
    (a trailing entry that records at compile time whether the relative pose was taken from the
    reference configuration; simulation does not read it), so the assignment fails to broadcast. Writing
    the same 11 values into the first 11 entries and leaving the last as compiled gives MetaWorld's
    weld on either MuJoCo.
    """

    model: mujoco.MjModel

    def reset_mocap_welds(self) -> None:
        if self.model.nmocap == 0:
            return
        for eq_id in range(self.model.neq):
            if self.model.eq_type[eq_id] == mujoco.mjtEq.mjEQ_WELD:
                self.model.eq_data[eq_id, : len(MOCAP_WELD_DATA)] = MOCAP_WELD_DATA


def make_metaworld_env(task: str) -> Any:
    """A MetaWorld ``SawyerXYZEnv`` of ``task`` that samples a new layout at every reset from its own
    ``np_random`` (so ``seed(s)`` before ``reset()`` fixes the layout) and observes its goal (the scripted
    experts read it). Imports metaworld here, so that the rest of ``gym_omnid`` never needs it."""
    try:
        from metaworld.env_dict import ALL_V3_ENVIRONMENTS
    except ImportError as e:
        raise ImportError(
            "the MetaWorld suite needs the optional dependency metaworld: "
            "pip install 'lerobot_policy_omnid[metaworld]'"
        ) from e
    task_cls = ALL_V3_ENVIRONMENTS[task]
    env_cls = type(f"{task_cls.__name__}OmniD", (_Mujoco4Welds, task_cls), {})
    env = env_cls()
    env._partially_observable = False  # the goal in the flat observation, as the experts expect
    del env.sawyer_observation_space  # recomputed with the goal's bounds (a cached property)
    env._freeze_rand_vec = False  # a new layout at every reset...
    env.seeded_rand_vec = True  # ...drawn from env.np_random, which env.seed() sets
    env._set_task_called = True  # no Task object: the layout is sampled, not replayed
    env.max_path_length = UNBOUNDED_STEPS
    return env


def _image_size(value: int | Sequence[int]) -> tuple[int, int]:
    """Normalise ``image_size`` (int or (height, width)) to (height, width), validated."""
    size = (value, value) if isinstance(value, int | np.integer) else tuple(value)
    if len(size) != 2 or not all(
        isinstance(s, int | np.integer) and not isinstance(s, bool) and 0 < s <= MAX_IMAGE_SIDE for s in size
    ):
        raise ValueError(
            f"image_size: expected an int or (height, width) of ints in [1, {MAX_IMAGE_SIDE}], got {value!r}"
        )
    return int(size[0]), int(size[1])


def _cameras(value: str | Sequence[str]) -> tuple[str, ...]:
    """Validate ``cameras``: a name or a sequence of distinct names from ``ALL_CAMERAS``, order kept."""
    cams = (value,) if isinstance(value, str) else tuple(value)
    if not cams or len(set(cams)) != len(cams) or not set(cams) <= set(ALL_CAMERAS):
        raise ValueError(
            f"cameras: expected a non-empty subset of {list(ALL_CAMERAS)} without repeats, got {value!r}"
        )
    return cams


def _close_at_exit(env_ref: weakref.ref) -> None:
    """Close a still-open env before MuJoCo's own exit hook terminates the EGL display."""
    env = env_ref()
    if env is not None:
        env.close()


def _turn_upright(model: mujoco.MjModel, cam_id: int) -> None:
    """Turn a fixed camera whose image up points down in the world 180 degrees about its optical axis."""
    world_R_mjcam = np.zeros(9)
    mujoco.mju_quat2Mat(world_R_mjcam, model.cam_quat[cam_id])
    if world_R_mjcam.reshape(3, 3)[2, 1] < 0:  # the camera's y (image up) has a downward world z
        turned = np.zeros(4)
        mujoco.mju_mulQuat(turned, model.cam_quat[cam_id], TURN_HALF)
        model.cam_quat[cam_id] = turned


class MetaWorldEnv(gym.Env):
    """A MetaWorld v3 task with images of several cameras, robot state and per-camera calibration.

    Observation: ``{"pixels": {cam: (H, W, 3) uint8}, "agent_pos": (STATE_DIM,) float32}`` with the state
    of ``state_names`` (hand position in m, gripper opening in [0, 1]); with ``per_frame_calibration``
    also ``"extrinsics.<cam>"`` (16,) and ``"intrinsics.<cam>"`` (9,) float32 of every observed camera, as
    ``gym_omnid``'s envs. Action: MetaWorld's ``(4,)`` float32 in [-1, 1] (``action_names``). Reward:
    MetaWorld's shaped reward; success (MetaWorld's ``info["success"]``) ends the episode and is
    ``info["is_success"]``. ``reset(seed=s)`` seeds MetaWorld's layout sampler first, so ``s`` always gives
    the same layout.

    Args:
        task: one of ``TASKS`` (MetaWorld v3 names, e.g. ``"assembly-v3"``).
        cameras: observed cameras, a non-empty subset of ``ALL_CAMERAS`` (order kept): the fixed
            ``FIXED_CAMERAS`` and the hand cameras ``HAND_CAMERAS``, whose calibration changes every step.
        image_size: int (square) or (height, width), pixels.
        per_frame_calibration: add each observed camera's calibration to every observation.
        blackout_cameras: observed cameras whose images are all zero (black, not rendered): a control in
            which only the state can drive a policy. The calibration entries stay.
        render_mode: ``"rgb_array"`` (``render()`` returns a mosaic of the observed cameras) or None.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": list(RENDER_MODES), "render_fps": CONTROL_FPS}

    def __init__(
        self,
        task: str,
        cameras: Sequence[str] = DEFAULT_CAMERAS,
        image_size: int | tuple[int, int] = DEFAULT_IMAGE_SIZE,
        per_frame_calibration: bool = False,
        blackout_cameras: Sequence[str] = (),
        render_mode: str | None = "rgb_array",
    ) -> None:
        if task not in TASKS:
            raise ValueError(f"task: expected one of {list(TASKS)}, got {task!r}")
        self.task = task
        self.cameras: tuple[str, ...] = _cameras(cameras)
        self.image_size: tuple[int, int] = _image_size(image_size)
        if not isinstance(per_frame_calibration, bool):
            raise ValueError(f"per_frame_calibration: expected True or False, got {per_frame_calibration!r}")
        self.per_frame_calibration = per_frame_calibration
        self.blackout_cameras = tuple(blackout_cameras)
        if not set(self.blackout_cameras) <= set(self.cameras) or len(set(self.blackout_cameras)) != len(
            self.blackout_cameras
        ):
            raise ValueError(
                f"blackout_cameras: expected distinct cameras among the observed {list(self.cameras)}, "
                f"got {list(blackout_cameras)}"
            )
        if render_mode not in (*RENDER_MODES, None):
            raise ValueError(f"render_mode: expected one of {[*RENDER_MODES, None]}, got {render_mode!r}")
        self.render_mode = render_mode
        self.state_names: list[str] = list(STATE_NAMES)
        self.action_names: list[str] = list(ACTION_NAMES)

        self._mw = make_metaworld_env(task)
        self.model: mujoco.MjModel = self._mw.model
        self.data: mujoco.MjData = self._mw.data
        height, width = self.image_size
        # Rendering only what the images need: no shadow maps, no multisampling, a buffer of image size.
        self.model.vis.global_.offwidth, self.model.vis.global_.offheight = width, height
        self.model.vis.quality.shadowsize = 0
        self.model.vis.quality.offsamples = 0
        for cam in FIXED_CAMERAS:
            _turn_upright(self.model, self.model.camera(cam).id)
        mujoco.mj_forward(self.model, self.data)
        self._cam_ids = {cam: self.model.camera(cam).id for cam in ALL_CAMERAS}
        self._renderer: mujoco.Renderer | None = None
        self._last_pixels: dict[str, np.ndarray] | None = None
        self._mw_obs: np.ndarray | None = None

        obs_spaces = {
            "pixels": spaces.Dict(
                [(cam, spaces.Box(0, 255, (height, width, 3), dtype=np.uint8)) for cam in self.cameras]
            ),
            "agent_pos": spaces.Box(
                np.array(STATE_LOW, np.float32), np.array(STATE_HIGH, np.float32), (STATE_DIM,), np.float32
            ),
        }
        if self.per_frame_calibration:
            for cam in self.cameras:
                for key, value in calibration_observation(cam, self.camera_calibration(cam)).items():
                    obs_spaces[key] = spaces.Box(-np.inf, np.inf, value.shape, dtype=np.float32)
        self.observation_space = spaces.Dict(obs_spaces)
        self.action_space = spaces.Box(-1.0, 1.0, (ACTION_DIM,), dtype=np.float32)

    # --- gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Sample a layout: with ``seed``, MetaWorld's sampler is seeded with it first."""
        super().reset(seed=seed)
        if seed is not None:
            self._mw.seed(seed)
        self._mw_obs, _ = self._mw.reset()
        return self._observation(), {"is_success": False}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        """One MetaWorld step; the episode terminates on MetaWorld's success."""
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (ACTION_DIM,):
            raise ValueError(f"action: expected shape ({ACTION_DIM},), got {action.shape}")
        action = np.clip(action, self.action_space.low, self.action_space.high)
        self._mw_obs, reward, _, _, mw_info = self._mw.step(action)
        success = bool(mw_info["success"])
        return self._observation(), float(reward), success, False, {"is_success": success}

    def render(self) -> np.ndarray | None:
        """Mosaic (rows of ``RENDER_MOSAIC_COLUMNS``) of the observed cameras' latest images, uint8."""
        if self.render_mode is None:
            return None
        if self._last_pixels is None:
            self._last_pixels = self._render_cameras()
        height, width = self.image_size
        columns = min(RENDER_MOSAIC_COLUMNS, len(self.cameras))
        rows = -(-len(self.cameras) // columns)
        mosaic = np.zeros((rows * height, columns * width, 3), dtype=np.uint8)
        for i, cam in enumerate(self.cameras):
            row, col = divmod(i, columns)
            image = self._last_pixels[cam]
            mosaic[row * height : (row + 1) * height, col * width : (col + 1) * width] = image
        return mosaic

    def close(self) -> None:
        """Free the renderer's GL context and MetaWorld's env."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self._mw.close()

    # --- public extras ---------------------------------------------------------------------------
    @property
    def task_description(self) -> str:
        """The task's name as an instruction (MetaWorld has no language annotations), e.g. "stick push"."""
        return self.task.removesuffix("-v3").replace("-", " ")

    def camera_calibration(self, cam: str) -> dict:
        """OpenCV calibration of camera ``cam`` (one of ``ALL_CAMERAS``) for this env's image size, now.

        The fixed cameras' never changes; a hand camera's follows the hand: after ``reset`` or ``step`` it
        is the one of the images just observed. Returns ``{"K": (3, 3), "T_cam_world": (4, 4), "image_size":
        (height, width)}`` in the convention of :mod:`gym_omnid.calibration`.
        """
        if cam not in ALL_CAMERAS:
            raise ValueError(f"cam: expected one of {list(ALL_CAMERAS)}, got {cam!r}")
        cam_id = self._cam_ids[cam]
        return mujoco_camera_calibration(
            float(self.model.cam_fovy[cam_id]),
            self.data.cam_xpos[cam_id],
            self.data.cam_xmat[cam_id],
            self.image_size,
        )

    def metaworld_observation(self) -> np.ndarray:
        """MetaWorld's flat observation (39,) of the current step, goal included (privileged: experts)."""
        if self._mw_obs is None:
            raise RuntimeError("metaworld_observation: call reset() first")
        return self._mw_obs

    # --- internals -------------------------------------------------------------------------------
    def _render_cameras(self) -> dict[str, np.ndarray]:
        """Render every observed camera with the one shared renderer (created on first use)."""
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, *self.image_size)
            # Registered after MuJoCo's EGL hook, so it runs first (atexit is LIFO).
            atexit.register(_close_at_exit, weakref.ref(self))
        pixels = {}
        for cam in self.cameras:
            if cam in self.blackout_cameras:
                pixels[cam] = np.zeros((*self.image_size, 3), dtype=np.uint8)
                continue
            self._renderer.update_scene(self.data, camera=self._cam_ids[cam])
            pixels[cam] = self._renderer.render()
        return pixels

    def _observation(self) -> dict:
        """Render the cameras and assemble ``{"pixels", "agent_pos"}``, with the cameras' calibration
        entries when ``per_frame_calibration``."""
        self._last_pixels = self._render_cameras()
        state = np.clip(self._mw_obs[:STATE_DIM], STATE_LOW, STATE_HIGH).astype(np.float32)
        obs: dict[str, Any] = {"pixels": dict(self._last_pixels), "agent_pos": state}
        if self.per_frame_calibration:
            for cam in self.cameras:
                obs.update(calibration_observation(cam, self.camera_calibration(cam)))
        return obs
