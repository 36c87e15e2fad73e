"""position_shift_m: the scene translated in training moves the cameras, the state's and the action's TCP
together, so the TCP stays where every camera sees it; metres become normalised units through the stats."""

import pytest
import torch
from gym_omnid import ACTION_DIM, STATE_DIM
from lerobot.policies.factory import make_policy
from omnid_testing import make_tiny_dataset, random_batch, tiny_config

from lerobot_omnid.geometry import apply_transform, project_to_pixels
from lerobot_omnid.policy.modeling_omnid import FRAME_MATRICES, OmniDPolicy

OBS = "observation.state"


def stats(width: float = 0.4) -> dict:
    """MIN_MAX statistics: every entry's range is ``width`` wide, from 0.3."""
    return {
        key: {"min": torch.full((dim,), 0.3), "max": torch.full((dim,), 0.3 + width)}
        for key, dim in (("observation.state", STATE_DIM), ("action", ACTION_DIM))
    }


def unnormalised(x: torch.Tensor, width: float = 0.4) -> torch.Tensor:
    return (x + 1) / 2 * width + 0.3


def test_a_shift_moves_the_cameras_the_state_and_the_action_consistently():
    policy = OmniDPolicy(tiny_config(position_shift_m=0.05, clip_sample_range=2.0), dataset_stats=stats())
    stacked = policy._stack_inputs(random_batch(policy.config), time_dim=True)
    actions = torch.rand(2, policy.config.horizon, ACTION_DIM) * 2 - 1
    shift_xy = torch.tensor([[0.04, -0.03], [-0.01, 0.05]])
    moved, moved_actions = policy._shift_positions(stacked, actions, shift_xy)
    shift = torch.nn.functional.pad(shift_xy, (0, 1))  # B, 3
    # TCP positions (x, y, z: the state's first three entries) move by the shift in metres, nothing else.
    tcp, moved_tcp = (unnormalised(s[OBS][..., :3]) for s in (stacked, moved))  # B, T, 3
    assert torch.allclose(moved_tcp, tcp + shift[:, None], atol=1e-5)
    assert torch.equal(moved[OBS][..., 2:], stacked[OBS][..., 2:])
    assert torch.allclose(
        unnormalised(moved_actions[..., :3]), unnormalised(actions[..., :3]) + shift[:, None]
    )
    assert torch.equal(moved_actions[..., 2:], actions[..., 2:])
    # Every camera sees the moved TCP where it saw the old one: the images stay true.
    pix_T_cam, cam_T_world = stacked[FRAME_MATRICES[0]], stacked[FRAME_MATRICES[1]]  # B, T, S, ...
    S = cam_T_world.shape[2]
    before = project_to_pixels(
        pix_T_cam, apply_transform(cam_T_world, tcp[:, :, None, None].expand(-1, -1, S, 1, 3))
    )
    after = project_to_pixels(
        pix_T_cam,
        apply_transform(moved[FRAME_MATRICES[1]], moved_tcp[:, :, None, None].expand(-1, -1, S, 1, 3)),
    )
    assert torch.allclose(after[0], before[0], atol=1e-3)
    assert not torch.allclose(moved[FRAME_MATRICES[1]], cam_T_world)


def test_training_with_a_shift_is_finite_and_off_outside_training(monkeypatch):
    torch.manual_seed(0)
    policy = OmniDPolicy(tiny_config(position_shift_m=0.05, clip_sample_range=2.0), dataset_stats=stats())
    calls = []
    original = policy._shift_positions
    monkeypatch.setattr(policy, "_shift_positions", lambda *a, **k: calls.append(1) or original(*a, **k))
    batch = random_batch(policy.config)
    loss, _ = policy.forward(batch)
    assert torch.isfinite(loss) and calls == [1]
    policy.eval()
    policy.forward(batch)
    assert calls == [1]  # evaluation losses see the data as recorded


def test_the_head_must_be_able_to_command_the_shifted_targets():
    # 5 cm over a 40 cm MIN_MAX range is 0.25 normalised units: a clip at 1.0 would cut them off. Checked
    # when training, so that a checkpoint loaded for inference with other statistics is not refused.
    policy = OmniDPolicy(tiny_config(position_shift_m=0.05), dataset_stats=stats())
    with pytest.raises(ValueError, match=r"clip_sample_range >= 1.25"):
        policy.forward(random_batch(policy.config))
    policy.eval()
    with torch.no_grad():
        policy.forward(random_batch(policy.config))
    unclipped = OmniDPolicy(tiny_config(position_shift_m=0.05, clip_sample=False), dataset_stats=stats())
    assert torch.isfinite(unclipped.forward(random_batch(unclipped.config))[0])


def test_without_stats_the_policy_loads_but_cannot_train_with_a_shift(tmp_path):
    policy = OmniDPolicy(tiny_config(position_shift_m=0.05, clip_sample_range=2.0))
    with pytest.raises(ValueError, match="needs the dataset's statistics"):
        policy.forward(random_batch(policy.config))
    policy.save_pretrained(tmp_path)
    config = OmniDPolicy.from_pretrained(tmp_path).config
    assert (config.position_shift_m, config.state_position_dims, config.action_position_dims) == (
        0.05,
        (0, 1),
        (0, 1),
    )
    with torch.no_grad():
        policy.eval()
        policy.forward(random_batch(policy.config))  # no shift outside training: no stats needed


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"position_shift_m": -0.01}, "`position_shift_m`: expected a half-width >= 0"),
        ({"action_position_dims": (0, 0)}, "`action_position_dims`: expected two distinct indices"),
        (
            {"position_shift_m": 0.05, "state_position_dims": (0, STATE_DIM)},
            "`state_position_dims`: expected indices below",
        ),
        (
            {"position_shift_m": 0.05, "use_ofg": False},
            "`position_shift_m`: expected 0.0 \\(off\\) with use_ofg=false",
        ),
    ],
)
def test_bad_shift_options_name_the_field(overrides, message):
    with pytest.raises(ValueError, match=message):
        OmniDPolicy(tiny_config(**overrides))


def test_make_policy_gives_the_shift_the_datasets_statistics(tmp_path):
    dataset = make_tiny_dataset(tmp_path / "data", cams=("cam_b",), size=32, episodes=1, frames=4)
    config = tiny_config(cams=("cam_b",), size=32, position_shift_m=0.01, clip_sample=False)
    policy = make_policy(config, ds_meta=dataset.meta)
    action = dataset.meta.stats["action"]
    expected = 2 / (torch.as_tensor(action["max"][:2]) - torch.as_tensor(action["min"][:2])).float()
    assert torch.allclose(policy.action_shift_scale, expected)
    state = dataset.meta.stats["observation.state"]
    expected = 2 / (torch.as_tensor(state["max"][:2]) - torch.as_tensor(state["min"][:2])).float()
    assert torch.allclose(policy.state_shift_scale, expected)
