"""``frozen_modules``: the parts named are not trained (no gradient, not given to the optimiser, kept in
eval mode), the others are; bad names are refused; the option survives a save and a reload."""

from __future__ import annotations

import pytest
import torch
from omnid_testing import random_batch, tiny_config

from lerobot_omnid.benchmark.commands import json_list
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

SIZE = 32
CAMS = ("cam_b", "cam_c")


def small_policy(**overrides) -> OmniDPolicy:
    config = tiny_config(
        CAMS, size=SIZE, volume_shape=(4, 4, 2), num_layers=1, down_dims=(16, 32), **overrides
    )
    torch.manual_seed(0)
    return OmniDPolicy(config)


def weights(module: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in module.parameters()]


@pytest.mark.parametrize("frozen", [("head",), ("backbone",), ("backbone", "head")])
def test_a_training_step_moves_only_what_is_not_frozen(frozen):
    policy = small_policy(frozen_modules=frozen)
    parts = {name: policy.model.part(name) for name in ("backbone", "ofg", "head")}
    before = {name: weights(part) for name, part in parts.items()}
    optimiser = torch.optim.AdamW(policy.get_optim_params(), lr=1e-2)
    policy.train()
    loss, _ = policy.forward(random_batch(policy.config, generator=torch.Generator().manual_seed(1)))
    loss.backward()
    optimiser.step()
    for name, part in parts.items():
        moved = any(not torch.equal(a, b) for a, b in zip(before[name], weights(part), strict=True))
        assert moved == (name not in frozen), name
        assert part.training == (name not in frozen), name
    trained = {id(p) for p in policy.get_optim_params()}
    for name, part in parts.items():
        assert all((id(p) in trained) == (name not in frozen) for p in part.parameters()), name


def test_without_an_ofg_ofg_freezes_the_keypoint_pooling():
    policy = small_policy(use_ofg=False, frozen_modules=("ofg",))
    assert policy.model.part("ofg") is policy.model.pool
    assert not any(p.requires_grad for p in policy.model.pool.parameters())


@pytest.mark.parametrize(
    ("frozen", "message"),
    [
        (("unet",), r"`frozen_modules`: expected some of \['backbone', 'ofg', 'head'\]"),
        (("backbone", "ofg", "head"), r"not all: something must train\), got \['backbone', 'ofg', 'head'\]"),
    ],
)
def test_bad_frozen_modules_are_named(frozen, message):
    with pytest.raises(ValueError, match=message):
        tiny_config(CAMS, size=SIZE, frozen_modules=frozen)


def test_frozen_modules_survive_save_and_load(tmp_path):
    policy = small_policy(frozen_modules=("head",))
    policy.save_pretrained(tmp_path)
    config = OmniDConfig.from_pretrained(tmp_path)
    assert config.frozen_modules == ("head",)
    loaded = OmniDPolicy.from_pretrained(tmp_path, config=config)
    assert not any(p.requires_grad for p in loaded.model.unet.parameters())
    assert all(p.requires_grad for p in loaded.model.backbone.parameters())


def test_the_command_line_form_parses_when_fine_tuning(tmp_path):
    """``--policy.frozen_modules`` as the protocols write it (JSON) parses over a saved checkpoint's config,
    as ``lerobot-train --policy.path=...`` does; a plain string is refused with the JSON form."""
    small_policy().config.save_pretrained(tmp_path)
    config = OmniDConfig.from_pretrained(tmp_path, cli_overrides=["--frozen_modules=" + json_list(("head",))])
    assert config.frozen_modules == ("head",)
    with pytest.raises(ValueError, match=r"expected a list of .*as JSON"):
        tiny_config(CAMS, size=SIZE, frozen_modules="head")
