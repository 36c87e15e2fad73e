"""Shared fixtures for the gym_omnid tests."""

from __future__ import annotations

from collections.abc import Iterator

import gym_omnid  # noqa: F401  (registers the envs)
import gymnasium as gym
import pytest
from gym_omnid.env import OmniDEnv


@pytest.fixture
def make_env() -> Iterator:
    """Factory ``make_env(task, **kwargs) -> OmniDEnv`` (unwrapped) that closes every env it made."""
    envs: list[gym.Env] = []

    def _make(task: str = "select_apple", **kwargs) -> OmniDEnv:
        env = gym.make(f"gym_omnid/{task}", **kwargs)
        envs.append(env)
        return env.unwrapped

    yield _make
    for env in envs:
        env.close()
