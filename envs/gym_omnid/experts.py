"""Scripted experts: the single entry point :func:`make_expert` and an episode runner.

Usage::

    obs, info = env.reset(seed=0)
    expert = make_expert(env.unwrapped)
    while True:
        obs, reward, terminated, truncated, info = env.step(expert.act())

The plan is computed once, right after ``reset``, from privileged simulator state (object poses) by the
task's :meth:`~gym_omnid.tasks.base.Task.plan_expert` (next to the task's geometry in its module under
:mod:`gym_omnid.tasks`): a list of named waypoints (:mod:`gym_omnid.waypoints`) replayed by one pure
interpolation function.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from gym_omnid.constants import MAX_EPISODE_STEPS
from gym_omnid.waypoints import GRASP_YAW, OPEN, Waypoint, interpolate, plan_length, waypoint_action

if TYPE_CHECKING:
    from gym_omnid.env import OmniDEnv

__all__ = [
    "ScriptedExpert",
    "Waypoint",
    "interpolate",
    "make_expert",
    "plan_length",
    "run_expert_episode",
    "waypoint_action",
]


class ScriptedExpert:
    """Replays a waypoint plan: ``act()`` returns the interpolated action of the next env step."""

    def __init__(self, start: Waypoint, waypoints: Sequence[Waypoint]) -> None:
        self.start = start
        self.waypoints = tuple(waypoints)
        self._step = 0

    def act(self) -> np.ndarray:
        """(ACTION_DIM,) float32 action for the next env step."""
        action = interpolate(self.start, self.waypoints, self._step)
        self._step += 1
        return action

    def __len__(self) -> int:
        return plan_length(self.waypoints)


def make_expert(env: OmniDEnv) -> ScriptedExpert:
    """Plan an expert for the episode just reset in ``env`` (the unwrapped :class:`OmniDEnv`)."""
    tcp_xyz, _ = env.tcp_pose()
    start = Waypoint("start", tuple(float(v) for v in tcp_xyz), GRASP_YAW, OPEN, 1)
    plan = env.task_spec.plan_expert(env.data, start)
    return ScriptedExpert(start, plan)


def run_expert_episode(
    env: gym.Env, seed: int, max_steps: int = MAX_EPISODE_STEPS, make: Callable[[Any], Any] = make_expert
) -> tuple[bool, int]:
    """Reset ``env`` (a gymnasium env, wrapped or not) with ``seed`` and run the expert ``make`` plans for
    it (one with an ``act()``; default: this package's) until the episode ends; returns (success, env steps
    taken)."""
    env.reset(seed=seed)
    expert = make(env.unwrapped)
    for step in range(1, max_steps + 1):
        _, _, terminated, truncated, info = env.step(expert.act())
        if terminated or truncated:
            return bool(info["is_success"]), step
    return False, max_steps
