"""OmniD for LeRobot: importing this package registers the ``omnid`` policy and env configs, and the
``omnid_sim`` robot and ``omnid_expert`` teleoperator."""

from lerobot_omnid import (
    env_config,  # noqa: F401  (registers --env.type=omnid)
    robot,  # noqa: F401  (registers --robot.type=omnid_sim, --teleop.type=omnid_expert)
)
from lerobot_omnid.policy.configuration_omnid import OmniDConfig

__all__ = ["OmniDConfig"]
