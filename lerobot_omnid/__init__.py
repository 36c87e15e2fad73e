"""OmniD for LeRobot: importing this package registers the ``omnid`` policy and env configs."""

from lerobot_omnid import env_config  # noqa: F401  (registers --env.type=omnid)
from lerobot_omnid.policy.configuration_omnid import OmniDConfig

__all__ = ["OmniDConfig"]
