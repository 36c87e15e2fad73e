"""``--env.type=omnid_metaworld``: MetaWorld v3 tasks with our cameras and calibration, for ``lerobot-eval``.

The env (:mod:`gym_omnid.metaworld_suite`, gym ids ``gym_omnid_metaworld/<task>``) observes the same keys
as ``--env.type=omnid``'s: ``pixels[<cam>]`` -> ``observation.images.<cam>``, ``agent_pos`` ->
``observation.state`` and, with ``per_frame_calibration`` (the default), each camera's calibration ->
``observation.extrinsics.<cam>`` / ``observation.intrinsics.<cam>``, the columns ``omnid-record --suite
metaworld`` writes. So any checkpoint trained on such a recording evaluates with the same cameras.
Needs the optional dependency ``metaworld`` (``pip install 'lerobot_policy_omnid[metaworld]'``) only when an
env is made; this module imports without it. LeRobot's own ``--env.type=metaworld`` is a different env
(one camera, no calibration).

Example::

    lerobot-eval --env.type=omnid_metaworld --env.task=assembly-v3 \\
        --policy.path=outputs/train/omnid_assembly/checkpoints/last/pretrained_model
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium as gym

# Importing gym_omnid.metaworld_suite registers the gym ids (gymnasium only; metaworld is not imported).
from gym_omnid.metaworld_suite.constants import (
    ACTION_DIM,
    ALL_CAMERAS,
    CONTROL_FPS,
    DEFAULT_CAMERAS,
    GYM_NAMESPACE,
    HAND_CAMERAS,
    MAX_EPISODE_STEPS,
    STATE_DIM,
    TASKS,
)
from lerobot.configs import PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import OBS_IMAGES

from lerobot_omnid.cli import check_choice, check_positive_int
from lerobot_omnid.env_config import (
    calibration_dict,
    env_policy_features,
    validate_blackout_cameras,
    validate_cameras,
    validate_image_size,
)

ENV_PACKAGE = "gym_omnid.metaworld_suite"
"""Python package that registers the gym ids ``gym_omnid_metaworld/<task>``."""


@EnvConfig.register_subclass("omnid_metaworld")
@dataclass
class OmniDMetaWorldEnvConfig(EnvConfig):
    """One MetaWorld v3 task seen by our cameras, with their calibration.

    The fields a user changes are ``task``, ``cameras`` and ``image_size`` (both must match the policy's
    training dataset). ``per_frame_calibration`` is on by default, as for ``--env.type=omnid``.

    Args:
        task: MetaWorld v3 task, one of ``gym_omnid.metaworld_suite.TASKS`` (e.g. ``assembly-v3``).
        cameras: Observed cameras: the fixed ``corner``, ``corner2``, ``corner3`` and the hand cameras
            ``behindGripper`` (default) and ``gripperPOV``, calibrated per frame. On the command line:
            ``--env.cameras='[corner,corner2]'``.
        image_size: Side of the square camera images, pixels.
        per_frame_calibration: Add every observed camera's calibration of the current frame to the
            observation (``observation.extrinsics.<cam>``, ``observation.intrinsics.<cam>``); needed by a
            policy that reads a hand camera's calibration.
        blackout_cameras: Observed cameras whose images are all black, for a control in which only the
            state can drive the policy (``--env.blackout_cameras='[corner,corner2]'``). Default: none.
        episode_length: Time limit of an episode, env steps (MetaWorld's horizon by default).
        fps: Control rate, steps per second; fixed by MetaWorld (80 Hz).
        render_mode: Gymnasium render mode; ``"rgb_array"`` gives ``lerobot-eval`` its videos (a mosaic
            of the observed cameras).
    """

    task: str | None = "assembly-v3"
    cameras: list[str] = field(default_factory=lambda: list(DEFAULT_CAMERAS))
    image_size: int = 128
    per_frame_calibration: bool = True
    blackout_cameras: list[str] = field(default_factory=list)
    episode_length: int = MAX_EPISODE_STEPS
    fps: int = CONTROL_FPS
    render_mode: str = "rgb_array"
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_choice("task", self.task, TASKS)
        self.cameras = validate_cameras("cameras", self.cameras, ALL_CAMERAS)
        validate_image_size("image_size", self.image_size)
        self.blackout_cameras = validate_blackout_cameras(self.blackout_cameras, self.cameras)
        if not isinstance(self.per_frame_calibration, bool):
            raise ValueError(
                f"`per_frame_calibration`: expected true or false, got {self.per_frame_calibration!r}"
            )
        check_positive_int("episode_length", self.episode_length)
        if self.fps != CONTROL_FPS:
            raise ValueError(
                f"fps: MetaWorld steps at a fixed {CONTROL_FPS} Hz; expected {CONTROL_FPS}, got {self.fps!r}"
            )
        check_choice("render_mode", self.render_mode, ("rgb_array",))
        # Derived from the fields above (a config loaded from JSON carries stale copies: rebuild).
        self.features, self.features_map = env_policy_features(
            self.cameras, self.image_size, STATE_DIM, ACTION_DIM, self.per_frame_calibration
        )

    @property
    def package_name(self) -> str:
        return ENV_PACKAGE

    @property
    def gym_id(self) -> str:
        return f"{GYM_NAMESPACE}/{self.task}"

    @property
    def gym_kwargs(self) -> dict:
        return {
            "cameras": tuple(self.cameras),
            "image_size": self.image_size,
            "per_frame_calibration": self.per_frame_calibration,
            "blackout_cameras": tuple(self.blackout_cameras),
            "render_mode": self.render_mode,
            "max_episode_steps": self.episode_length,
        }

    def camera_calibrations(self) -> dict[str, dict]:
        """Calibration of each observed camera, keyed like the policy's image features (builds the env
        once): ``{"observation.images.<cam>": CameraCalibration.to_dict()}``. Fixed cameras only: a hand
        camera's calibration changes every frame."""
        moving = [cam for cam in self.cameras if cam in HAND_CAMERAS]
        if moving:
            raise ValueError(
                f"cameras: {moving} move with the hand and have no static calibration; expected fixed "
                f"cameras only, got {self.cameras} (their per-frame calibration: per_frame_calibration=True)"
            )
        env = gym.make(self.gym_id, disable_env_checker=True, **self.gym_kwargs)
        try:
            return {
                f"{OBS_IMAGES}.{cam}": calibration_dict(env.unwrapped, cam, f"{OBS_IMAGES}.{cam}")
                for cam in self.cameras
            }
        finally:
            env.close()
