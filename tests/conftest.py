"""Fixtures shared by the tests; helpers live in ``omnid_testing.py``."""

import os

import pytest
import torch

os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(autouse=True)
def _seed() -> None:
    torch.manual_seed(0)
