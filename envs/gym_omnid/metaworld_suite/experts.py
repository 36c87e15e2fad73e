"""MetaWorld's scripted policies as experts with ``gym_omnid``'s interface: ``make_expert(env).act()``.

Usage::

    obs, info = env.reset(seed=0)
    expert = make_expert(env.unwrapped)
    while True:
        obs, reward, terminated, truncated, info = env.step(expert.act())

Each task has one policy in ``metaworld.policies`` (e.g. ``SawyerAssemblyV3Policy``); it reads MetaWorld's
flat observation (object and goal positions: privileged state), which the env keeps for it.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

import gym_omnid.experts

if TYPE_CHECKING:
    from gym_omnid.metaworld_suite.env import MetaWorldEnv


class MetaWorldExpert:
    """``act()`` returns the scripted policy's action for the env's current MetaWorld observation."""

    def __init__(self, env: MetaWorldEnv, policy: Any) -> None:
        self.env = env
        self.policy = policy

    def act(self) -> np.ndarray:
        """(ACTION_DIM,) float32 action for the next env step, in [-1, 1]."""
        with warnings.catch_warnings():
            # The policies warn whenever their proportional gains saturate; the env clips, as MetaWorld.
            warnings.filterwarnings("ignore", message="Constant\\(s\\) may be too high")
            action = self.policy.get_action(self.env.metaworld_observation())
        return np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0)


def make_expert(env: MetaWorldEnv) -> MetaWorldExpert:
    """The scripted expert of ``env.task`` (``env`` the unwrapped :class:`MetaWorldEnv`, just reset)."""
    from metaworld.policies import ENV_POLICY_MAP

    return MetaWorldExpert(env, ENV_POLICY_MAP[env.task]())


def run_expert_episode(env: Any, seed: int, max_steps: int) -> tuple[bool, int]:
    """Reset ``env`` (a gymnasium env, wrapped or not) with ``seed`` and run MetaWorld's expert until the
    episode ends or ``max_steps`` steps; returns (success, env steps taken)."""
    return gym_omnid.experts.run_expert_episode(env, seed, max_steps, make=make_expert)
