"""Multi-view MuJoCo benchmark envs for OmniD (gymnasium + mujoco + numpy only).

Importing this package registers ``gym_omnid/<task>`` for every task in ``TASKS``; variants are
constructor kwargs (``cameras``, ``layout``, ``background``, ``image_size``, ``rig``,
``per_frame_calibration``, ``blackout_cameras``, ``blackout_from_step``, ``camera_offsets``,
``task_onehot``)::

    env = gymnasium.make("gym_omnid/select_apple", layout="position_ood", background="ood2")

Rendering is headless: ``MUJOCO_GL`` defaults to ``egl`` here when unset (set ``MUJOCO_GL=osmesa``
where no EGL is available).
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before anything imports mujoco

from gymnasium.envs.registration import register

from gym_omnid.constants import (
    ACTION_DIM,
    ACTION_NAMES,
    ALL_CAMERAS,
    BACKGROUNDS,
    CAMERAS,
    CONTROL_FPS,
    DEFAULT_RIG,
    LAYOUTS,
    MAX_EPISODE_STEPS,
    RIGS,
    STATE_DIM,
    STATE_NAMES,
    TASKS,
    TRAIN_CAMERAS,
    WORKSPACE_BOUNDS,
    WRIST_CAMERA,
)

for _task in TASKS:
    register(
        id=f"gym_omnid/{_task}",
        entry_point="gym_omnid.env:OmniDEnv",
        max_episode_steps=MAX_EPISODE_STEPS,
        kwargs={"task": _task},
    )

__all__ = [
    "ACTION_DIM",
    "ACTION_NAMES",
    "ALL_CAMERAS",
    "BACKGROUNDS",
    "CAMERAS",
    "CONTROL_FPS",
    "DEFAULT_RIG",
    "LAYOUTS",
    "MAX_EPISODE_STEPS",
    "RIGS",
    "STATE_DIM",
    "STATE_NAMES",
    "TASKS",
    "TRAIN_CAMERAS",
    "WORKSPACE_BOUNDS",
    "WRIST_CAMERA",
]
