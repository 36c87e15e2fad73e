"""OmniDEnv: one gymnasium env for every task, camera subset, layout, background and image size."""

from __future__ import annotations

import atexit
import weakref
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from gym_omnid.calibration import calibration_observation, mujoco_camera_calibration
from gym_omnid.camera_offsets import apply_camera_offsets, check_camera_offsets
from gym_omnid.constants import (
    ACTION_DIM,
    ACTION_NAMES,
    ACTION_POS_HIGH,
    ACTION_POS_LOW,
    ALL_CAMERAS,
    ARM_JOINT_RANGES,
    ARM_JOINTS,
    BACKGROUNDS,
    CAMERAS,
    CONTROL_FPS,
    DEFAULT_IMAGE_SIZE,
    DEFAULT_RIG,
    ENV_STATE_OBS_KEY,
    FINGER_TRAVEL,
    HOME_JOINTS,
    LAYOUTS,
    MAX_IMAGE_SIDE,
    N_SUBSTEPS,
    RENDER_MOSAIC_COLUMNS,
    RIGS,
    SETTLE_STEPS,
    STATE_DIM,
    STATE_GRIPPER_RANGE,
    STATE_JOINT_MARGIN,
    STATE_NAMES,
    STATE_POS_BOUND,
    STATE_ROT_BOUND,
    TABLE_TEXTURE_SIZE,
    TASK_ONEHOT_NAMES,
    TASKS,
)
from gym_omnid.ik import DampedLeastSquaresIK
from gym_omnid.rigs import RIG_PLACEMENTS
from gym_omnid.robot import FINGER_JOINTS, TCP_SITE
from gym_omnid.rotations import matrix_from_rot6d, rot6d_from_matrix
from gym_omnid.scene import TABLE_TEXTURE, build_mjcf
from gym_omnid.tasks import Task, make_task, task_onehot
from gym_omnid.textures import BACKGROUND_TEXTURES

RENDER_MODES = ("rgb_array",)


def _choice(field: str, value: Any, allowed: Sequence[Any]) -> Any:
    """Return ``value`` if it is one of ``allowed``, else raise a ValueError naming ``field``."""
    if value not in allowed:
        raise ValueError(f"{field}: expected one of {list(allowed)}, got {value!r}")
    return value


def _image_size(value: int | Sequence[int]) -> tuple[int, int]:
    """Normalise ``image_size`` (int or (height, width)) to (height, width), validated."""
    if isinstance(value, int | np.integer):
        size = (value, value)
    elif isinstance(value, Sequence) and not isinstance(value, str):
        size = tuple(value)
    else:
        size = ()
    if len(size) != 2 or not all(
        isinstance(s, int | np.integer) and not isinstance(s, bool) and 0 < s <= MAX_IMAGE_SIDE for s in size
    ):
        raise ValueError(
            f"image_size: expected an int or (height, width) of ints in [1, {MAX_IMAGE_SIDE}], got {value!r}"
        )
    return int(size[0]), int(size[1])


def _state_bounds() -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of ``agent_pos`` in the ``STATE_NAMES`` layout."""
    joints = np.array(ARM_JOINT_RANGES)
    low = [
        *[-STATE_POS_BOUND] * 3,
        *[-STATE_ROT_BOUND] * 6,
        STATE_GRIPPER_RANGE[0],
        *(joints[:, 0] - STATE_JOINT_MARGIN),
    ]
    high = [
        *[STATE_POS_BOUND] * 3,
        *[STATE_ROT_BOUND] * 6,
        STATE_GRIPPER_RANGE[1],
        *(joints[:, 1] + STATE_JOINT_MARGIN),
    ]
    return np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)


def _cameras(value: Sequence[str]) -> tuple[str, ...]:
    """Validate ``cameras`` (a name or a sequence of distinct names from ``ALL_CAMERAS``), order kept."""
    cams = (value,) if isinstance(value, str) else tuple(value)
    if not cams or len(set(cams)) != len(cams) or not set(cams) <= set(ALL_CAMERAS):
        raise ValueError(
            f"cameras: expected a non-empty subset of {list(ALL_CAMERAS)} without repeats, got {value!r}"
        )
    return cams


def _blackout_cameras(value: Sequence[str], cameras: tuple[str, ...]) -> tuple[str, ...]:
    """Validate ``blackout_cameras``: distinct names among the observed ``cameras`` (possibly none)."""
    blackout = (value,) if isinstance(value, str) else tuple(value)
    if len(set(blackout)) != len(blackout) or not set(blackout) <= set(cameras):
        raise ValueError(
            f"blackout_cameras: expected distinct cameras among the observed {list(cameras)}, got {value!r}"
        )
    return blackout


def _blackout_from_step(value: int, blackout: tuple[str, ...]) -> int:
    """Validate ``blackout_from_step``: an int >= 0; above 0 only with ``blackout_cameras`` to black out."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise ValueError(f"blackout_from_step: expected an int >= 0 (env steps), got {value!r}")
    if value and not blackout:
        raise ValueError(
            f"blackout_from_step: expected 0 without blackout_cameras (nothing to black out), got {value}"
        )
    return int(value)


def _close_at_exit(env_ref: weakref.ref) -> None:
    """Close a still-open env before MuJoCo's own exit hook terminates the EGL display."""
    env = env_ref()
    if env is not None:
        env.close()


class OmniDEnv(gym.Env):
    """Multi-view tabletop manipulation with a 6-DoF arm, five fixed cameras, a wrist camera and
    scripted experts.

    Observation: ``{"pixels": {cam: (H, W, 3) uint8}, "agent_pos": (STATE_DIM,) float32}`` with the
    state layout of ``state_names`` (TCP position m, TCP 6D orientation, gripper closure in [0, 1],
    arm joint positions rad). With ``per_frame_calibration`` also, for every observed camera,
    ``"extrinsics.<cam>"`` (16,) and ``"intrinsics.<cam>"`` (9,) float32: ``T_cam_world`` and ``K`` of
    that frame, row-major (``camera_calibration(cam)`` when the images were rendered). With ``task_onehot``
    also ``"environment_state"`` (``ENV_STATE_OBS_KEY``): ``(len(TASKS),) float32``, 1 at the index of
    ``task`` in ``TASKS`` (``TASK_ONEHOT_NAMES``), 0 elsewhere, which tells a policy trained on several
    tasks which one it is asked for.
    Action: ``(ACTION_DIM,) float32``, an absolute TCP target in the world frame: position (m), 6D
    orientation (first two columns of ``world_R_tcp``), gripper command in [0, 1] (0 open, 1 closed);
    applied through damped-least-squares IK to the joint-position actuators, then
    ``1 / CONTROL_FPS`` s of physics.

    Args:
        task: one of ``TASKS``.
        cameras: observed cameras, a non-empty subset of ``ALL_CAMERAS`` (order kept): the five fixed
            ``CAMERAS`` (the default) and ``WRIST_CAMERA`` (``cam_wrist``, on the gripper).
        layout: ``"id"`` (key objects within +-5 cm of nominal), ``"position_ood"`` (5-10 cm away) or a
            graded band ``"position_band_1"`` .. ``"position_band_4"`` (0-2.5 ... 7.5-10 cm outside the ID
            square, ``POSITION_BANDS``); distances in L-inf.
        background: table texture, ``"id"`` or ``"ood1"`` .. ``"ood4"``.
        image_size: int (square) or (height, width), pixels.
        blackout_cameras: observed cameras whose observed pixels are all zero (black), for controls in which
            only the state can drive a policy; ``render()`` still shows what they see. Default: none.
        blackout_from_step: the ``blackout_cameras`` go black from this env step of every episode on (0: the
            observation of ``reset``; k: the observation after the k-th ``step``), a camera dying mid-episode.
        camera_offsets: cameras moved from their placement by a small rigid delta, per camera ``[rx, ry, rz,
            tx, ty, tz]`` (rotation vector in degrees, translation in metres, camera frame;
            :mod:`gym_omnid.camera_offsets`): a bumped camera. ``camera_calibration`` is the moved camera's.
        rig: placements of the fixed cameras, one of ``RIGS`` (see :mod:`gym_omnid.rigs`).
        per_frame_calibration: add each observed camera's calibration to every observation.
        task_onehot: add the task as a one-hot over ``TASKS`` (``"environment_state"``) to every
            observation.
        render_mode: ``"rgb_array"`` (``render()`` returns a mosaic of the observed cameras) or None.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": list(RENDER_MODES), "render_fps": CONTROL_FPS}

    def __init__(
        self,
        task: str,
        cameras: Sequence[str] = CAMERAS,
        layout: str = "id",
        background: str = "id",
        image_size: int | tuple[int, int] = DEFAULT_IMAGE_SIZE,
        rig: str = DEFAULT_RIG,
        per_frame_calibration: bool = False,
        render_mode: str | None = "rgb_array",
        blackout_cameras: Sequence[str] = (),
        blackout_from_step: int = 0,
        camera_offsets: Mapping[str, Sequence[float]] | None = None,
        task_onehot: bool = False,
    ) -> None:
        self.task: str = _choice("task", task, TASKS)
        self.cameras: tuple[str, ...] = _cameras(cameras)
        self.layout: str = _choice("layout", layout, LAYOUTS)
        self.background: str = _choice("background", background, BACKGROUNDS)
        self.image_size: tuple[int, int] = _image_size(image_size)
        self.blackout_cameras: tuple[str, ...] = _blackout_cameras(blackout_cameras, self.cameras)
        self.blackout_from_step: int = _blackout_from_step(blackout_from_step, self.blackout_cameras)
        self.camera_offsets: dict[str, tuple[float, ...]] = check_camera_offsets(camera_offsets)
        self.rig: str = _choice("rig", rig, RIGS)
        if not isinstance(per_frame_calibration, bool):
            raise ValueError(f"per_frame_calibration: expected True or False, got {per_frame_calibration!r}")
        self.per_frame_calibration = per_frame_calibration
        if not isinstance(task_onehot, bool):
            raise ValueError(f"task_onehot: expected True or False, got {task_onehot!r}")
        self.task_onehot = task_onehot
        self.render_mode = _choice("render_mode", render_mode, (*RENDER_MODES, None))
        self.state_names: list[str] = list(STATE_NAMES)
        self.action_names: list[str] = list(ACTION_NAMES)

        self._task = make_task(task)
        mjcf = build_mjcf(self._task, self.image_size, RIG_PLACEMENTS[self.rig])
        self.model = mujoco.MjModel.from_xml_string(mjcf)
        apply_camera_offsets(self.model, self.camera_offsets)
        self.data = mujoco.MjData(self.model)
        self._task.bind(self.model)
        self._ik = DampedLeastSquaresIK(self.model, TCP_SITE, ARM_JOINTS)
        self._tcp = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, TCP_SITE)
        self._arm_qpos = self._qpos_adr(ARM_JOINTS)
        self._finger_qpos = self._qpos_adr(FINGER_JOINTS)
        self._arm_ctrl = self._actuator_ids(ARM_JOINTS)
        self._finger_ctrl = self._actuator_ids(FINGER_JOINTS)
        self._q_target = np.array(HOME_JOINTS)
        self._renderer: mujoco.Renderer | None = None
        self._last_pixels: dict[str, np.ndarray] | None = None
        self._steps = 0  # env steps since the last reset
        self.set_background(self.background)

        height, width = self.image_size
        obs_spaces = {
            # A sequence of pairs keeps the cameras in the requested order (a dict would be sorted).
            "pixels": spaces.Dict(
                [(cam, spaces.Box(0, 255, (height, width, 3), dtype=np.uint8)) for cam in self.cameras]
            ),
            "agent_pos": spaces.Box(*_state_bounds(), (STATE_DIM,), dtype=np.float32),
        }
        if self.per_frame_calibration:
            for cam in self.cameras:
                for key, value in calibration_observation(cam, self.camera_calibration(cam)).items():
                    obs_spaces[key] = spaces.Box(-np.inf, np.inf, value.shape, dtype=np.float32)
        if self.task_onehot:
            obs_spaces[ENV_STATE_OBS_KEY] = spaces.Box(0, 1, (len(TASK_ONEHOT_NAMES),), dtype=np.float32)
        self.observation_space = spaces.Dict(obs_spaces)
        low = np.array([*ACTION_POS_LOW, *([-1.0] * 6), 0.0], dtype=np.float32)
        high = np.array([*ACTION_POS_HIGH, *([1.0] * 6), 1.0], dtype=np.float32)
        self.action_space = spaces.Box(low, high, (ACTION_DIM,), dtype=np.float32)
        self._reset_robot()
        mujoco.mj_forward(self.model, self.data)

    # --- gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Home the arm, sample a layout with ``self.np_random`` and let the objects settle."""
        super().reset(seed=seed)
        self._steps = 0
        mujoco.mj_resetData(self.model, self.data)
        self._reset_robot()
        self._task.reset(self.data, self.np_random, self.layout)
        mujoco.mj_forward(self.model, self.data)
        mujoco.mj_step(self.model, self.data, nstep=SETTLE_STEPS)
        return self._observation(), {"is_success": self._task.is_success(self.data)}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        """Apply an absolute TCP target for ``1 / CONTROL_FPS`` s; reward 1 and terminate on success."""
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (ACTION_DIM,):
            raise ValueError(f"action: expected shape ({ACTION_DIM},), got {action.shape}")
        action = np.clip(action, self.action_space.low, self.action_space.high)
        world_R_target = matrix_from_rot6d(action[3:9])
        self._q_target = self._ik.solve(action[:3], world_R_target, self._q_target)
        self.data.ctrl[self._arm_ctrl] = self._q_target
        self.data.ctrl[self._finger_ctrl] = (1.0 - action[9]) * FINGER_TRAVEL
        mujoco.mj_step(self.model, self.data, nstep=N_SUBSTEPS)
        self._task.after_step(self.data)
        self._steps += 1
        success = self._task.is_success(self.data)
        return self._observation(), float(success), success, False, {"is_success": success}

    def render(self) -> np.ndarray | None:
        """Mosaic (rows of ``RENDER_MOSAIC_COLUMNS``) of the observed cameras' latest images, uint8."""
        if self.render_mode is None:
            return None
        if self._last_pixels is None:
            self._last_pixels = self._render_cameras()
        images = [self._last_pixels[cam] for cam in self.cameras]
        height, width = self.image_size
        columns = min(RENDER_MOSAIC_COLUMNS, len(images))
        rows = -(-len(images) // columns)
        mosaic = np.zeros((rows * height, columns * width, 3), dtype=np.uint8)
        for i, image in enumerate(images):
            row, col = divmod(i, columns)
            mosaic[row * height : (row + 1) * height, col * width : (col + 1) * width] = image
        return mosaic

    def close(self) -> None:
        """Free the renderer's GL context."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # --- public extras ---------------------------------------------------------------------------
    @property
    def task_description(self) -> str:
        """Language instruction of the current episode (e.g. ``"put the apple in the bowl"``)."""
        return self._task.description

    def camera_calibration(self, cam: str) -> dict:
        """OpenCV calibration of camera ``cam`` (one of ``ALL_CAMERAS``) for this env's image size, now.

        The fixed cameras' never changes (their ``camera_offsets`` included); the wrist camera's follows
        the arm: after ``reset`` or ``step``
        it is the one of the images just observed (MuJoCo's camera poses are those the renderer used).
        Returns ``{"K": (3, 3) float64, "T_cam_world": (4, 4) float64, "image_size": (height, width)}``
        where ``uv = K @ (T_cam_world @ X)[:3]`` divided by its third component, pixel centres at
        integer coordinates (see :mod:`gym_omnid.calibration`).
        """
        _choice("cam", cam, ALL_CAMERAS)
        cam_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, cam)
        return mujoco_camera_calibration(
            float(self.model.cam_fovy[cam_id]),
            self.data.cam_xpos[cam_id],
            self.data.cam_xmat[cam_id],
            self.image_size,
        )

    def object_positions(self) -> dict[str, np.ndarray]:
        """World xyz (3,) of the task's key objects, metres."""
        return self._task.object_positions(self.data)

    def set_background(self, background: str) -> None:
        """Swap the table texture in place (``tex_data`` + re-upload to the GL context), no recompiling."""
        self.background = _choice("background", background, BACKGROUNDS)
        tex_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_TEXTURE, TABLE_TEXTURE)
        adr = self.model.tex_adr[tex_id]
        n_bytes = TABLE_TEXTURE_SIZE * TABLE_TEXTURE_SIZE * 3
        self.model.tex_data[adr : adr + n_bytes] = BACKGROUND_TEXTURES[background](
            TABLE_TEXTURE_SIZE
        ).reshape(-1)
        if self._renderer is not None:
            # The renderer owns the GL context holding the uploaded textures (private attribute).
            if self._renderer._gl_context is not None:
                self._renderer._gl_context.make_current()
            mujoco.mjr_uploadTexture(self.model, self._renderer._mjr_context, tex_id)
            self._last_pixels = None

    @property
    def task_spec(self) -> Task:
        """The :class:`gym_omnid.tasks.Task` instance (privileged access for experts and tests)."""
        return self._task

    def tcp_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Measured TCP position (3,) in metres and ``world_R_tcp`` (3, 3)."""
        return self.data.site_xpos[self._tcp].copy(), self.data.site_xmat[self._tcp].reshape(3, 3).copy()

    # --- internals -------------------------------------------------------------------------------
    def _qpos_adr(self, joints: Sequence[str]) -> np.ndarray:
        """qpos addresses of single-dof joints."""
        return np.array([self.model.jnt_qposadr[self.model.joint(name).id] for name in joints])

    def _actuator_ids(self, names: Sequence[str]) -> np.ndarray:
        """Actuator ids by name."""
        return np.array([self.model.actuator(name).id for name in names])

    def _reset_robot(self) -> None:
        """Arm at home, gripper open, actuator targets matching."""
        self._q_target = np.array(HOME_JOINTS)
        self.data.qpos[self._arm_qpos] = self._q_target
        self.data.ctrl[self._arm_ctrl] = self._q_target
        self.data.qpos[self._finger_qpos] = FINGER_TRAVEL
        self.data.ctrl[self._finger_ctrl] = FINGER_TRAVEL

    def _render_cameras(self) -> dict[str, np.ndarray]:
        """Render every observed camera with the one shared renderer (created on first use)."""
        if self._renderer is None:
            height, width = self.image_size
            self._renderer = mujoco.Renderer(self.model, height, width)
            # Registered after MuJoCo's EGL hook, so it runs first (atexit is LIFO).
            atexit.register(_close_at_exit, weakref.ref(self))
        pixels = {}
        for cam in self.cameras:
            self._renderer.update_scene(self.data, camera=cam)
            pixels[cam] = self._renderer.render()
        return pixels

    def _observation(self) -> dict:
        """Render the cameras and assemble ``{"pixels", "agent_pos"}`` in the ``state_names`` layout (the
        ``blackout_cameras`` black from ``blackout_from_step`` on), with the cameras' calibration entries
        when ``per_frame_calibration`` and the task one-hot when ``task_onehot``."""
        self._last_pixels = self._render_cameras()
        tcp_xyz, world_R_tcp = self.tcp_pose()
        finger_gap = float(np.sum(self.data.qpos[self._finger_qpos]))
        state = np.concatenate(
            [
                tcp_xyz,
                rot6d_from_matrix(world_R_tcp),
                [1.0 - finger_gap / (2 * FINGER_TRAVEL)],
                self.data.qpos[self._arm_qpos],
            ]
        ).astype(np.float32)
        black = self.blackout_cameras if self._steps >= self.blackout_from_step else ()
        pixels = {cam: np.zeros_like(im) if cam in black else im for cam, im in self._last_pixels.items()}
        obs = {"pixels": pixels, "agent_pos": state}
        if self.per_frame_calibration:
            for cam in self.cameras:
                obs.update(calibration_observation(cam, self.camera_calibration(cam)))
        if self.task_onehot:
            obs[ENV_STATE_OBS_KEY] = task_onehot(self.task)
        return obs
