"""Names of the sim robot's scalar features, in LeRobot's robot conventions.

A LeRobot robot reports flat dicts of named floats; ``lerobot-rollout`` keeps only the scalar features
whose names end in ``.pos`` or ``.vel`` (``lerobot/rollout/context.py``) for the policy's state and
action, so every name here ends in ``.pos``, also the orientation entries and the gripper. They are the
``gym_omnid`` names (``gym_omnid.ACTION_NAMES``, ``gym_omnid.STATE_NAMES``) with that suffix; a joint
``shoulder_pan_pos`` becomes ``shoulder_pan.pos``, as on LeRobot's arms. The measured state's first
entries have the action's names (TCP pose and gripper), as a real arm reports ``<motor>.pos`` for both
its present and its goal position.
"""

from __future__ import annotations

from gym_omnid.constants import ACTION_NAMES, STATE_NAMES

POS_SUFFIX = ".pos"


def robot_feature_name(env_name: str) -> str:
    """``ee_x`` -> ``ee_x.pos``; ``shoulder_pan_pos`` -> ``shoulder_pan.pos``."""
    return env_name.removesuffix("_pos") + POS_SUFFIX


ACTION_KEYS: tuple[str, ...] = tuple(robot_feature_name(n) for n in ACTION_NAMES)
"""The robot's action keys, in the order of the env's action vector."""

STATE_KEYS: tuple[str, ...] = tuple(robot_feature_name(n) for n in STATE_NAMES)
"""The robot's scalar observation keys, in the order of the env's ``agent_pos``."""
