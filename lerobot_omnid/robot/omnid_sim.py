"""``OmniDSim``: the ``gym_omnid`` scene as a LeRobot ``Robot`` (``--robot.type=omnid_sim``).

Observation (``observation_features``): the measured state as named floats (``features.STATE_KEYS``: TCP
position m, TCP 6D orientation, gripper closure 0 open .. 1 closed, six joint angles rad) and one
``(height, width, 3)`` uint8 RGB image per configured camera, under the camera's robot name.
Action (``action_features``): ``features.ACTION_KEYS``, an absolute TCP target in the robot base frame
and a gripper command, as the env's action vector. Each ``send_action`` applies it for one control step
(0.1 s of physics) and renders the cameras; ``get_observation`` returns that latest state.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from functools import cached_property
from typing import Any

import gymnasium as gym
import numpy as np
from gym_omnid.constants import MAX_EPISODE_STEPS
from lerobot.robots.robot import Robot
from lerobot.utils.decorators import check_if_already_connected, check_if_not_connected
from lerobot.utils.errors import DeviceNotConnectedError

from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.env_config import ENV_PACKAGE, calibration_dict
from lerobot_omnid.keys import image_key
from lerobot_omnid.robot.config_omnid_sim import ROBOT_TYPE, OmniDSimCameraConfig, OmniDSimConfig
from lerobot_omnid.robot.features import ACTION_KEYS, STATE_KEYS

logger = logging.getLogger(__name__)


class OmniDSim(Robot):
    """The simulated arm, its table scene and its fixed cameras; see :class:`OmniDSimConfig`.

    ``connect`` builds the scene and resets it with ``config.seed``; one connection is one scene.
    ``camera_calibration`` gives each camera's calibration in OmniD's convention, for the images this
    robot returns.
    """

    config_class = OmniDSimConfig
    name = ROBOT_TYPE

    def __init__(self, config: OmniDSimConfig) -> None:
        super().__init__(config)
        self.config = config
        # LeRobot reads len(robot.cameras) to size its image writers.
        self.cameras: dict[str, OmniDSimCameraConfig] = dict(config.cameras)
        self._env: gym.Env | None = None
        self._obs: dict[str, Any] | None = None
        self._steps = 0
        self._succeeded_at: int | None = None
        self._warned_long_scene = False

    # --- features --------------------------------------------------------------------------------
    @cached_property
    def observation_features(self) -> dict[str, type | tuple]:
        height, width = self.config.image_size
        return {
            **dict.fromkeys(STATE_KEYS, float),
            **{name: (height, width, 3) for name in self.cameras},
        }

    @cached_property
    def action_features(self) -> dict[str, type]:
        return dict.fromkeys(ACTION_KEYS, float)

    # --- connection ------------------------------------------------------------------------------
    @property
    def is_connected(self) -> bool:
        return self._env is not None

    @check_if_already_connected
    def connect(self, calibrate: bool = True) -> None:
        """Build the scene and reset it with ``config.seed`` (``calibrate`` has nothing to do here)."""
        cfg = self.config
        env = gym.make(
            f"{ENV_PACKAGE}/{cfg.task}",
            cameras=tuple(cam.source for cam in self.cameras.values()),
            layout=cfg.layout,
            background=cfg.background,
            image_size=cfg.image_size,
            rig=cfg.rig,
            disable_env_checker=True,
        )
        try:
            obs, _ = env.reset(seed=cfg.seed)
        except BaseException:
            env.close()
            raise
        self._env, self._obs = env, obs
        self._steps, self._succeeded_at, self._warned_long_scene = 0, None, False
        logger.info(
            "%s connected: %s, layout %s, background %s, seed %d, rig %s, cameras %s at %dx%d: %r",
            self.name,
            cfg.task,
            cfg.layout,
            cfg.background,
            cfg.seed,
            cfg.rig,
            {name: cam.source for name, cam in self.cameras.items()},
            cfg.image_size[1],
            cfg.image_size[0],
            env.unwrapped.task_description,
        )

    @property
    def is_calibrated(self) -> bool:
        return True

    def calibrate(self) -> None:
        """No motors to calibrate; camera calibration: :meth:`camera_calibration`."""

    def configure(self) -> None:
        """Nothing to configure."""

    @check_if_not_connected
    def disconnect(self) -> None:
        """Close the scene; logs how many actions were applied and whether the task succeeded."""
        self._env.close()
        self._env, self._obs = None, None
        outcome = f"succeeded after {self._succeeded_at} steps" if self._succeeded_at else "not solved"
        logger.info("%s disconnected after %d actions; task %s", self.name, self._steps, outcome)

    # --- the scene -------------------------------------------------------------------------------
    @property
    def task_description(self) -> str:
        """The scene's language instruction (what ``--dataset.single_task`` / ``--task`` should say)."""
        return self._scene().task_description

    @property
    def steps(self) -> int:
        """Actions applied since ``connect``."""
        return self._steps

    @property
    def is_success(self) -> bool:
        """Whether the task has succeeded at some step since ``connect``."""
        return self._succeeded_at is not None

    @check_if_not_connected
    def camera_calibration(self, camera: str) -> CameraCalibration:
        """Calibration of the robot camera ``camera`` (its robot name) for the images this robot returns."""
        if camera not in self.cameras:
            raise KeyError(
                f"camera: expected one of the robot's cameras {list(self.cameras)}, got {camera!r}"
            )
        source = self.cameras[camera].source
        return CameraCalibration.from_dict(
            calibration_dict(self._scene(), source, image_key(camera)), camera=image_key(camera)
        )

    # --- observation and action ------------------------------------------------------------------
    @check_if_not_connected
    def get_observation(self) -> dict[str, Any]:
        """The state after the latest action (or the reset): named floats and one image per camera."""
        obs = self._obs
        state = obs["agent_pos"]
        out: dict[str, Any] = {key: float(v) for key, v in zip(STATE_KEYS, state, strict=True)}
        for name, cam in self.cameras.items():
            out[name] = obs["pixels"][cam.source].copy()
        return out

    @check_if_not_connected
    def send_action(self, action: Mapping[str, Any]) -> dict[str, float]:
        """Apply one action for one control step; returns the action applied (clipped to the action space).

        ``action`` must hold every key of ``action_features``. The state's other keys (the joint angles,
        which this robot does not take as commands) are ignored, so that LeRobot's return to the initial
        position, which sends the observed ``.pos`` values, works; any other key is an error.
        """
        missing = [key for key in ACTION_KEYS if key not in action]
        unknown = sorted(key for key in action if key not in STATE_KEYS)
        if missing or unknown:
            raise ValueError(
                f"action: expected the keys {list(ACTION_KEYS)}"
                + (f"; missing {missing}" if missing else "")
                + (f"; unknown {unknown}" if unknown else "")
            )
        values = []
        for key in ACTION_KEYS:
            try:
                value = float(action[key])
            except (TypeError, ValueError) as e:
                raise ValueError(f"action[{key!r}]: expected a number, got {action[key]!r}") from e
            if not math.isfinite(value):
                raise ValueError(f"action[{key!r}]: expected a finite number, got {value}")
            values.append(value)
        env = self._scene()
        applied = np.clip(np.asarray(values, dtype=np.float32), env.action_space.low, env.action_space.high)
        self._obs, _, _, _, info = self._env.step(applied)
        self._steps += 1
        if info["is_success"] and self._succeeded_at is None:
            self._succeeded_at = self._steps
            logger.info("%s: task succeeded after %d steps", self.name, self._steps)
        if self._steps > MAX_EPISODE_STEPS and not self._warned_long_scene:
            self._warned_long_scene = True
            logger.warning(
                "%s: %d actions in one scene, more than the env's %d-step episodes. The scene is reset only "
                "by connect(), so further episodes of this run show the same, finished scene: record one "
                "episode per lerobot-record run (--dataset.num_episodes=1, a new --robot.seed and "
                "--teleop.seed each) and merge the datasets; see docs/real_robot.md.",
                self.name,
                self._steps,
                MAX_EPISODE_STEPS,
            )
        return {key: float(v) for key, v in zip(ACTION_KEYS, applied, strict=True)}

    def _scene(self) -> Any:
        """The unwrapped ``gym_omnid`` env (raises when not connected)."""
        if self._env is None:
            raise DeviceNotConnectedError(f"{self} is not connected. Run `.connect()` first.")
        return self._env.unwrapped
