"""``--env.type=omnid``: the multi-view MuJoCo benchmark envs (package ``gym_omnid``) for ``lerobot-eval``.

LeRobot builds ``gym.make(f"gym_omnid/{task}", **gym_kwargs)`` from this config and maps the env's
observation ``pixels[<cam>]`` to ``observation.images.<cam>`` and ``agent_pos`` to ``observation.state``.

Example::

    lerobot-eval --env.type=omnid --env.task=select_apple --env.layout=position_ood \\
        --env.cameras='[cam_b,cam_c,cam_d,cam_e]' --policy.path=outputs/train/omnid/checkpoints/last/...
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

# Importing gym_omnid.constants imports gym_omnid, which registers the gym ids (gymnasium only, cheap).
from gym_omnid.constants import (
    ACTION_DIM,
    BACKGROUNDS,
    CAMERAS,
    CONTROL_FPS,
    LAYOUTS,
    MAX_EPISODE_STEPS,
    MAX_IMAGE_SIDE,
    STATE_DIM,
    TASKS,
    TRAIN_CAMERAS,
)
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.cli import check_choice, check_positive_int

ENV_PACKAGE = "gym_omnid"
"""Python package that registers the gym ids ``gym_omnid/<task>``."""


def validate_cameras(field_name: str, cameras: Any) -> list[str]:
    """Check a camera list: non-empty, known names, no duplicates. Returns it as a list."""
    if isinstance(cameras, str) or not isinstance(cameras, list | tuple) or not cameras:
        raise ValueError(
            f"{field_name}: expected a non-empty list of cameras from {list(CAMERAS)}, got {cameras!r}"
        )
    unknown = [c for c in cameras if c not in CAMERAS]
    if unknown:
        raise ValueError(
            f"{field_name}: unknown camera(s) {unknown}; expected names from {list(CAMERAS)}, "
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


@EnvConfig.register_subclass("omnid")
@dataclass
class OmniDEnvConfig(EnvConfig):
    """One task of the OmniD multi-view benchmark, in one evaluation setting.

    The fields a user changes are ``task``, ``layout`` and ``background`` (the evaluation setting),
    ``cameras`` (must match the cameras the policy was trained on) and ``image_size`` (must match the
    training dataset's images).

    Args:
        task: Benchmark task, one of ``gym_omnid.constants.TASKS``.
        cameras: Fixed cameras whose images are observed, from ``cam_a`` ... ``cam_e``. Default: the
            training cameras B, C, D, E (camera A is the unseen view of the few-shot protocol).
            On the command line: ``--env.cameras='[cam_b,cam_c]'``.
        layout: Object placement: ``"id"`` (the 10 cm x 10 cm square seen in training),
            ``"position_ood"`` (the band from 10 to 20 cm around it) or a graded band ``"position_band_1"``
            ... ``"position_band_4"`` (0-2.5, 2.5-5, 5-7.5, 7.5-10 cm outside the square).
        background: Table texture: ``"id"`` or one of the unseen ``"ood1"`` ... ``"ood4"``.
        image_size: Side of the square camera images, pixels.
        blackout_cameras: Observed cameras whose images are all black (zero pixels), for a control in which
            only the state can drive the policy. Default: none. ``--env.blackout_cameras='[cam_b,cam_c]'``.
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
    blackout_cameras: list[str] = field(default_factory=list)
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
        self.blackout_cameras = validate_blackout_cameras(self.blackout_cameras, self.cameras)
        check_positive_int("episode_length", self.episode_length)
        if self.fps != CONTROL_FPS:
            raise ValueError(
                f"fps: the omnid envs step at a fixed {CONTROL_FPS} Hz; expected {CONTROL_FPS}, "
                f"got {self.fps!r}"
            )
        check_choice("render_mode", self.render_mode, ("rgb_array",))

        # Derived from the fields above (a config loaded from JSON carries stale copies: rebuild).
        self.features = {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(ACTION_DIM,)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(STATE_DIM,)),
        }
        self.features_map = {ACTION: ACTION, "agent_pos": OBS_STATE}
        for cam in self.cameras:
            self.features[f"pixels/{cam}"] = PolicyFeature(
                type=FeatureType.VISUAL, shape=(self.image_size, self.image_size, 3)
            )
            self.features_map[f"pixels/{cam}"] = f"{OBS_IMAGES}.{cam}"

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
            "blackout_cameras": tuple(self.blackout_cameras),
            "render_mode": self.render_mode,
            "max_episode_steps": self.episode_length,
        }

    def camera_calibrations(self) -> dict[str, dict]:
        """Calibration of each observed camera, keyed like the policy's image features.

        Builds the env once. Returns ``{"observation.images.<cam>": CameraCalibration.to_dict()}`` for
        images of ``image_size``: what a dataset recorded in this setting stores in its feature info.
        """
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
