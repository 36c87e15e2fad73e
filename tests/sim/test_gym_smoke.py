"""Smoke test: the registered env builds, resets and steps with the documented API."""

from __future__ import annotations

import gym_omnid
import numpy as np


def test_make_reset_step(make_env) -> None:
    env = make_env("select_apple")
    obs, info = env.reset(seed=0)
    assert set(obs["pixels"]) == set(gym_omnid.CAMERAS)
    assert obs["agent_pos"].shape == (gym_omnid.STATE_DIM,)
    assert info == {"is_success": False}
    obs, _, _, _, info = env.step(env.action_space.sample())
    assert obs in env.observation_space
    assert "is_success" in info
    assert env.task_description == "put the apple in the bowl"
    assert len(env.state_names) == gym_omnid.STATE_DIM and len(env.action_names) == gym_omnid.ACTION_DIM
    assert np.isfinite(obs["agent_pos"]).all()
