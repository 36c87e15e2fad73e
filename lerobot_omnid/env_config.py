"""``--env.type=omnid``: the multi-view MuJoCo benchmark envs (package ``gym_omnid``) for ``lerobot-eval``.

LeRobot builds ``gym.make(f"gym_omnid/{task}", **gym_kwargs)`` from this config and maps the env's
observation ``pixels[<cam>]`` to ``observation.images.<cam>`` and ``agent_pos`` to ``observation.state``;
with ``per_frame_calibration`` (the default) also ``extrinsics.<cam>`` / ``intrinsics.<cam>`` to the
dataset columns ``observation.extrinsics.<cam>`` / ``observation.intrinsics.<cam>``
(:mod:`lerobot_omnid.calibration.frame_columns`) that ``omnid-record`` writes by default; with
``task_onehot`` also ``environment_state`` (the task as a one-hot) to ``observation.environment_state``, the
column of ``omnid-record --task-onehot``. A policy reads only the keys it was made with, so the columns are
harmless to one that does not use them (an OmniD checkpoint with its calibration in ``config.json``,
LeRobot's stock policies): LeRobot's normaliser and the policies' observation queues skip keys outside
their features.

Example::

    lerobot-eval --env.type=omnid --env.task=select_apple --env.layout=position_ood \\
        --env.cameras='[cam_b,cam_c,cam_d,cam_e]' --policy.path=outputs/train/omnid/checkpoints/last/...
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

# Importing gym_omnid.constants imports gym_omnid, which registers the gym ids (gymnasium only, cheap).
from gym_omnid.calibration import EXTRINSICS_OBS_PREFIX, INTRINSICS_OBS_PREFIX
from gym_omnid.camera_offsets import check_camera_offsets
from gym_omnid.constants import (
    ACTION_DIM,
    ALL_CAMERAS,
    BACKGROUNDS,
    CONTROL_FPS,
    DEFAULT_RIG,
    ENV_STATE_OBS_KEY,
    LAYOUTS,
    MAX_EPISODE_STEPS,
    MAX_IMAGE_SIDE,
    RIGS,
    STATE_DIM,
    TASK_ONEHOT_NAMES,
    TASKS,
    TRAIN_CAMERAS,
    WRIST_CAMERA,
)
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

from lerobot_omnid.calibration.frame_columns import (
    EXTRINSICS_NAMES,
    INTRINSICS_NAMES,
    extrinsics_key,
    intrinsics_key,
)
from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.cli import check_choice, check_positive_int

ENV_PACKAGE = "gym_omnid"
"""Python package that registers the gym ids ``gym_omnid/<task>``."""


def validate_cameras(field_name: str, cameras: Any, allowed: Sequence[str] = ALL_CAMERAS) -> list[str]:
    """Check a camera list: non-empty, names from ``allowed`` (default: gym_omnid's), no duplicates.
    Returns it as a list."""
    if isinstance(cameras, str) or not isinstance(cameras, list | tuple) or not cameras:
        raise ValueError(
            f"{field_name}: expected a non-empty list of cameras from {list(allowed)}, got {cameras!r}"
        )
    unknown = [c for c in cameras if c not in allowed]
    if unknown:
        raise ValueError(
            f"{field_name}: unknown camera(s) {unknown}; expected names from {list(allowed)}, "
            f"got {list(cameras)}"
        )
    if len(set(cameras)) != len(cameras):
        raise ValueError(f"{field_name}: expected distinct cameras, got {list(cameras)}")
    return list(cameras)


def validate_blackout_cameras(blackout: Any, cameras: list[str]) -> list[str]:
    """Check ``blackout_cameras``: a list (possibly empty) of distinct cameras among the observed ones."""
    if isinstance(blackout, str) or not isinstance(blackout, list | tuple):
        raise ValueError(f"blackout_cameras: expected a list of cameras from {cameras}, got {blackout!r}")
    if len(set(blackout)) != len(blackout) or not set(blackout) <= set(cameras):
        raise ValueError(
            f"blackout_cameras: expected distinct cameras among the observed {cameras}, got {list(blackout)}"
        )
    return list(blackout)


def validate_image_size(field_name: str, image_size: Any) -> int:
    """Check a square image side in pixels."""
    if (
        isinstance(image_size, bool)
        or not isinstance(image_size, int)
        or not 1 <= image_size <= MAX_IMAGE_SIDE
    ):
        raise ValueError(
            f"{field_name}: expected an int number of pixels in [1, {MAX_IMAGE_SIDE}], got {image_size!r}"
        )
    return image_size


def env_policy_features(
    cameras: Sequence[str],
    image_size: int,
    state_dim: int,
    action_dim: int,
    per_frame_calibration: bool,
    env_state_dim: int = 0,
) -> tuple[dict[str, PolicyFeature], dict[str, str]]:
    """``(features, features_map)`` of an env config whose env observes ``pixels/<cam>`` images of
    ``image_size``, ``agent_pos``, with ``per_frame_calibration`` each camera's calibration entries and, when
    ``env_state_dim`` > 0, an ``environment_state`` of that width (``observation.environment_state``, which
    LeRobot's DP and ACT and OmniD condition on)."""
    features = {
        ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(action_dim,)),
        "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(state_dim,)),
    }
    features_map = {ACTION: ACTION, "agent_pos": OBS_STATE}
    for cam in cameras:
        features[f"pixels/{cam}"] = PolicyFeature(type=FeatureType.VISUAL, shape=(image_size, image_size, 3))
        features_map[f"pixels/{cam}"] = f"{OBS_IMAGES}.{cam}"
    if per_frame_calibration:
        # STATE, as LeRobot's dataset_to_policy_features types these columns of a dataset.
        for cam in cameras:
            for prefix, key, names in (
                (EXTRINSICS_OBS_PREFIX, extrinsics_key(cam), EXTRINSICS_NAMES),
                (INTRINSICS_OBS_PREFIX, intrinsics_key(cam), INTRINSICS_NAMES),
            ):
                features[prefix + cam] = PolicyFeature(type=FeatureType.STATE, shape=(len(names),))
                features_map[prefix + cam] = key
    if env_state_dim:
        # ENV, as LeRobot's dataset_to_policy_features types observation.environment_state.
        features[ENV_STATE_OBS_KEY] = PolicyFeature(type=FeatureType.ENV, shape=(env_state_dim,))
        features_map[ENV_STATE_OBS_KEY] = OBS_ENV_STATE
    return features, features_map


@EnvConfig.register_subclass("omnid")
@dataclass
class OmniDEnvConfig(EnvConfig):
    """One task of the OmniD multi-view benchmark, in one evaluation setting.

    The fields a user changes are ``task``, ``layout``, ``background`` and ``rig`` (the evaluation
    setting), ``cameras`` (must match the cameras the policy was trained on), ``image_size`` (must match
    the training dataset's images), ``task_onehot`` (must be on for a policy trained on datasets recorded
    with ``--task-onehot``). ``per_frame_calibration`` is on by default, so a policy trained on
    ``omnid-record``'s per-frame calibration columns gets them; turning it off only drops keys that other
    policies ignore.

    Args:
        task: Benchmark task, one of ``gym_omnid.constants.TASKS``.
        cameras: Cameras whose images are observed: the fixed ``cam_a`` ... ``cam_e`` and the wrist camera
            ``cam_wrist``. Default: the training cameras B, C, D, E (camera A is the unseen view of the
            few-shot protocol). On the command line: ``--env.cameras='[cam_b,cam_c]'``.
        layout: Object placement: ``"id"`` (the 10 cm x 10 cm square seen in training),
            ``"position_ood"`` (the band from 10 to 20 cm around it) or a graded band ``"position_band_1"``
            ... ``"position_band_4"`` (0-2.5, 2.5-5, 5-7.5, 7.5-10 cm outside the square).
        background: Table texture: ``"id"`` or one of the unseen ``"ood1"`` ... ``"ood4"``.
        image_size: Side of the square camera images, pixels.
        rig: Placements of the five fixed cameras, one of ``gym_omnid.RIGS``: ``"default"`` (the
            benchmark's), ``"closer"``, ``"higher"``, ``"bumped"`` (every camera moved 8-17 cm and turned
            5-14 degrees). ``--env.rig=bumped``.
        per_frame_calibration: Add every observed camera's calibration of the current frame to the
            observation, which ``lerobot-eval`` passes to the policy as ``observation.extrinsics.<cam>``
            (16 values, ``T_cam_world`` row-major) and ``observation.intrinsics.<cam>`` (9, ``K``), the
            columns ``omnid-record`` writes by default. On by default; policies that do not read the
            columns ignore them. With ``camera_offsets`` the columns are the moved camera's: a policy that
            reads them sees the move. ``--env.per_frame_calibration=false`` drops them.
        blackout_cameras: Observed cameras whose images are all black (zero pixels), for a control in which
            only the state can drive the policy. Default: none. ``--env.blackout_cameras='[cam_b,cam_c]'``.
        blackout_from_step: The ``blackout_cameras`` go black from this env step of each episode on (0: from
            the first observation), a camera dying mid-episode. ``--env.blackout_from_step=100``.
        camera_offsets: Cameras moved after calibration (a bumped camera: the images change, the policy's
            calibration does not): per camera ``[rx, ry, rz, tx, ty, tz]``, a rotation vector in degrees
            and a translation in metres in the camera's OpenCV frame, ``T_cam_world' = [R(r) | t] @
            T_cam_world`` (``gym_omnid.camera_offsets``). Default: none.
            ``--env.camera_offsets='{cam_b: [0,0,2,0.02,0,0]}'``.
        task_onehot: Add the task as a one-hot over ``gym_omnid.constants.TASKS`` (in that order) to the
            observation, which ``lerobot-eval`` passes to the policy as ``observation.environment_state``
            (6 values, FeatureType.ENV), the column ``omnid-record --task-onehot`` writes: a policy trained
            on several tasks' datasets merged is told which task it is asked for. Off by default; needed by a
            policy trained with the column. ``--env.task_onehot=true``.
        episode_length: Time limit of an episode, env steps (at ``fps`` steps per second).
        fps: Control rate, steps per second; fixed by the env (10 Hz).
        render_mode: Gymnasium render mode; ``"rgb_array"`` gives ``lerobot-eval`` its videos (a mosaic
            of the observed cameras).
    """

    task: str | None = "select_apple"
    cameras: list[str] = field(default_factory=lambda: list(TRAIN_CAMERAS))
    layout: str = "id"
    background: str = "id"
    image_size: int = 128
    rig: str = DEFAULT_RIG
    per_frame_calibration: bool = True
    blackout_cameras: list[str] = field(default_factory=list)
    blackout_from_step: int = 0
    camera_offsets: dict[str, list[float]] = field(default_factory=dict)
    task_onehot: bool = False
    episode_length: int = MAX_EPISODE_STEPS
    fps: int = CONTROL_FPS
    render_mode: str = "rgb_array"
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_choice("task", self.task, TASKS)
        self.cameras = validate_cameras("cameras", self.cameras)
        check_choice("layout", self.layout, LAYOUTS)
        check_choice("background", self.background, BACKGROUNDS)
        validate_image_size("image_size", self.image_size)
        check_choice("rig", self.rig, RIGS)
        if not isinstance(self.per_frame_calibration, bool):
            raise ValueError(
                f"`per_frame_calibration`: expected true or false, got {self.per_frame_calibration!r}"
            )
        self.blackout_cameras = validate_blackout_cameras(self.blackout_cameras, self.cameras)
        if isinstance(self.blackout_from_step, bool) or not isinstance(self.blackout_from_step, int):
            raise ValueError(f"`blackout_from_step`: expected an int >= 0, got {self.blackout_from_step!r}")
        if self.blackout_from_step < 0 or (self.blackout_from_step and not self.blackout_cameras):
            raise ValueError(
                "`blackout_from_step`: expected an int >= 0, and 0 without `blackout_cameras`, got "
                f"{self.blackout_from_step!r} with blackout_cameras {self.blackout_cameras}"
            )
        offsets = check_camera_offsets(self.camera_offsets)  # its errors name camera_offsets and the camera
        self.camera_offsets = {cam: list(offset) for cam, offset in offsets.items()}
        if not isinstance(self.task_onehot, bool):
            raise ValueError(f"`task_onehot`: expected true or false, got {self.task_onehot!r}")
        check_positive_int("episode_length", self.episode_length)
        if self.fps != CONTROL_FPS:
            raise ValueError(
                f"fps: the omnid envs step at a fixed {CONTROL_FPS} Hz; expected {CONTROL_FPS}, "
                f"got {self.fps!r}"
            )
        check_choice("render_mode", self.render_mode, ("rgb_array",))

        # Derived from the fields above (a config loaded from JSON carries stale copies: rebuild).
        self.features, self.features_map = env_policy_features(
            self.cameras,
            self.image_size,
            STATE_DIM,
            ACTION_DIM,
            self.per_frame_calibration,
            env_state_dim=len(TASK_ONEHOT_NAMES) if self.task_onehot else 0,
        )

    @property
    def package_name(self) -> str:
        return ENV_PACKAGE

    @property
    def gym_kwargs(self) -> dict:
        return {
            "cameras": tuple(self.cameras),
            "layout": self.layout,
            "background": self.background,
            "image_size": self.image_size,
            "rig": self.rig,
            "per_frame_calibration": self.per_frame_calibration,
            "blackout_cameras": tuple(self.blackout_cameras),
            "blackout_from_step": self.blackout_from_step,
            "camera_offsets": {cam: tuple(offset) for cam, offset in self.camera_offsets.items()},
            "task_onehot": self.task_onehot,
            "render_mode": self.render_mode,
            "max_episode_steps": self.episode_length,
        }

    def camera_calibrations(self) -> dict[str, dict]:
        """Calibration of each observed camera, keyed like the policy's image features.

        Builds the env once. Returns ``{"observation.images.<cam>": CameraCalibration.to_dict()}`` for
        images of ``image_size``: what a dataset recorded in this setting with ``--static-calibration``
        stores in its feature info (and, per frame, in the columns of one recorded by default). The
        wrist camera has none (it moves): its calibration is per frame.
        """
        if WRIST_CAMERA in self.cameras:
            raise ValueError(
                f"cameras: {WRIST_CAMERA} moves with the arm and has no static calibration; expected fixed "
                f"cameras only, got {self.cameras} (its per-frame calibration: per_frame_calibration=True)"
            )
        env = gym.make(self.gym_id, disable_env_checker=True, **self.gym_kwargs)
        try:
            return {
                f"{OBS_IMAGES}.{cam}": calibration_dict(env.unwrapped, cam, f"{OBS_IMAGES}.{cam}")
                for cam in self.cameras
            }
        finally:
            env.close()


def calibration_dict(env: Any, cam: str, key: str) -> dict[str, Any]:
    """Validated JSON form of ``env.camera_calibration(cam)`` (numpy arrays), errors naming ``key``."""
    raw = env.camera_calibration(cam)
    data = {
        "K": raw["K"].tolist(),
        "T_cam_world": raw["T_cam_world"].tolist(),
        "image_size": [int(s) for s in raw["image_size"]],
    }
    return CameraCalibration.from_dict(data, camera=key).to_dict()
