"""OmniD for LeRobot: importing this package registers the ``omnid`` policy config, the ``omnid`` and
``omnid_metaworld`` env configs, and the ``omnid_sim`` robot and ``omnid_expert`` teleoperator."""

from lerobot_omnid import (
    env_config,  # noqa: F401  (registers --env.type=omnid)
    env_config_metaworld,  # noqa: F401  (registers --env.type=omnid_metaworld; metaworld not imported)
    robot,  # noqa: F401  (registers --robot.type=omnid_sim, --teleop.type=omnid_expert)
)
from lerobot_omnid.policy.configuration_omnid import OmniDConfig

__all__ = ["OmniDConfig"]
