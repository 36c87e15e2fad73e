"""MetaWorld v3 tasks as multi-view, calibrated gymnasium envs (optional: needs ``metaworld``).

Importing this package registers ``gym_omnid_metaworld/<task>`` for every task in ``TASKS`` (string
entry points: metaworld itself is imported only when an env is made)::

    env = gymnasium.make("gym_omnid_metaworld/assembly-v3", image_size=128, per_frame_calibration=True)

The observation has the format of ``gym_omnid``'s envs (``pixels``, ``agent_pos`` and, per camera,
``extrinsics.<cam>`` / ``intrinsics.<cam>``), so ``omnid-record`` and the OmniD policy take either suite.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before anything imports mujoco

from gymnasium.envs.registration import register

from gym_omnid.metaworld_suite.constants import (
    ACTION_DIM,
    ACTION_NAMES,
    ALL_CAMERAS,
    CONTROL_FPS,
    DEFAULT_CAMERAS,
    FIXED_CAMERAS,
    GYM_NAMESPACE,
    HAND_CAMERA,
    HAND_CAMERAS,
    MAX_EPISODE_STEPS,
    STATE_DIM,
    STATE_NAMES,
    TASKS,
)

for _task in TASKS:
    register(
        id=f"{GYM_NAMESPACE}/{_task}",
        entry_point="gym_omnid.metaworld_suite.env:MetaWorldEnv",
        max_episode_steps=MAX_EPISODE_STEPS,
        kwargs={"task": _task},
    )

__all__ = [
    "ACTION_DIM",
    "ACTION_NAMES",
    "ALL_CAMERAS",
    "CONTROL_FPS",
    "DEFAULT_CAMERAS",
    "FIXED_CAMERAS",
    "GYM_NAMESPACE",
    "HAND_CAMERA",
    "HAND_CAMERAS",
    "MAX_EPISODE_STEPS",
    "STATE_DIM",
    "STATE_NAMES",
    "TASKS",
]
