"""Pre/post-processing pipelines of OmniD: LeRobot's own steps (rename, batch, device, normalise)."""

from __future__ import annotations

from typing import Any

import torch
from lerobot.processor import PolicyAction, PolicyProcessorPipeline, make_default_pre_post_processors

from lerobot_omnid.policy.configuration_omnid import OmniDConfig


def make_omnid_pre_post_processors(
    config: OmniDConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    """The same pipelines as LeRobot's DiffusionPolicy.

    Pre-processing renames features, adds a batch dimension, moves to the device and normalises
    state and action (images are left in [0, 1]: ``normalization_mapping["VISUAL"]`` is IDENTITY and the
    backbone applies a fixed normalisation, so unseen cameras need no statistics). Post-processing
    unnormalises actions and moves them to the CPU.
    """
    return make_default_pre_post_processors(config, dataset_stats)
