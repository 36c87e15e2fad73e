"""``OmniDExpert``: the scripted expert of ``gym_omnid`` as a LeRobot ``Teleoperator``
(``--teleop.type=omnid_expert``), producing the actions of ``--robot.type=omnid_sim``.

``connect`` rebuilds the robot's scene from the same task, layout and seed (a one-camera, tiny-image
copy: the reset does not depend on cameras, image size or table texture), plans the expert on it
(``gym_omnid.experts.make_expert``, from the object poses after the reset) and closes it again; each
``get_action`` returns the plan's next action as the robot's named action dict.
"""

from __future__ import annotations

import logging

import gymnasium as gym
from gym_omnid.experts import ScriptedExpert, make_expert
from lerobot.teleoperators.teleoperator import Teleoperator
from lerobot.utils.decorators import check_if_already_connected, check_if_not_connected

from lerobot_omnid.env_config import ENV_PACKAGE
from lerobot_omnid.robot.config_omnid_expert import TELEOP_TYPE, OmniDExpertConfig
from lerobot_omnid.robot.features import ACTION_KEYS

logger = logging.getLogger(__name__)

PLANNING_CAMERA = "cam_a"
PLANNING_IMAGE_SIZE = 8  # px: the planning copy of the scene renders once, at reset; nothing looks at it


class OmniDExpert(Teleoperator):
    """The expert for one scene; see :class:`OmniDExpertConfig`."""

    config_class = OmniDExpertConfig
    name = TELEOP_TYPE

    def __init__(self, config: OmniDExpertConfig) -> None:
        super().__init__(config)
        self.config = config
        self._expert: ScriptedExpert | None = None
        self._actions_given = 0

    @property
    def action_features(self) -> dict[str, type]:
        return dict.fromkeys(ACTION_KEYS, float)

    @property
    def feedback_features(self) -> dict[str, type]:
        return {}

    @property
    def is_connected(self) -> bool:
        return self._expert is not None

    @check_if_already_connected
    def connect(self, calibrate: bool = True) -> None:
        """Plan the expert for the scene of ``config.task`` / ``layout`` / ``seed``."""
        cfg = self.config
        env = gym.make(
            f"{ENV_PACKAGE}/{cfg.task}",
            cameras=(PLANNING_CAMERA,),
            layout=cfg.layout,
            image_size=PLANNING_IMAGE_SIZE,
            disable_env_checker=True,
        )
        try:
            env.reset(seed=cfg.seed)
            self._expert = make_expert(env.unwrapped)
        finally:
            env.close()
        self._actions_given = 0
        logger.info(
            "%s connected: %s, layout %s, seed %d, a plan of %d steps",
            self.name,
            cfg.task,
            cfg.layout,
            cfg.seed,
            len(self._expert),
        )

    @property
    def is_calibrated(self) -> bool:
        return True

    def calibrate(self) -> None:
        """Nothing to calibrate."""

    def configure(self) -> None:
        """Nothing to configure."""

    @property
    def plan_length(self) -> int:
        """Steps until the plan's last waypoint (held afterwards); 0 before ``connect``."""
        return len(self._expert) if self._expert is not None else 0

    @check_if_not_connected
    def get_action(self) -> dict[str, float]:
        """The plan's action for the next control step."""
        action = self._expert.act()
        self._actions_given += 1
        return {key: float(v) for key, v in zip(ACTION_KEYS, action, strict=True)}

    def send_feedback(self, feedback: dict[str, float]) -> None:
        """The expert takes no feedback (its plan is open loop)."""

    @check_if_not_connected
    def disconnect(self) -> None:
        logger.info(
            "%s disconnected after %d actions (plan: %d)", self, self._actions_given, len(self._expert)
        )
        self._expert = None
