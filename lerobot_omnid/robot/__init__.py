"""The sim robot and its expert teleoperator as LeRobot plugins: importing this package registers
``--robot.type=omnid_sim`` and ``--teleop.type=omnid_expert`` (the device classes are found by LeRobot's
naming convention, ``config_<name>`` -> ``<name>``)."""

from lerobot_omnid.robot import config_omnid_expert, config_omnid_sim  # noqa: F401  (registration)
