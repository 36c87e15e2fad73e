"""The richer plane readouts: condition shapes, image dependence, gradients, save/load; and the pieces each
adds over the keypoints (a presence that a softmax ignores, several latents, a convolution's layout)."""

import pytest
import torch
from omnid_testing import STATE_DIM, random_batch, tiny_config

from lerobot_omnid.policy.modeling_omnid import OmniDPolicy
from lerobot_omnid.policy.plane_readout import BEVConvReadout, KeypointFeatureReadout, LatentQueryReadout

SIZE = 64
CHANNELS, DIM, LATENTS = 3, 5, 2


def readout_config(readout: str):
    return tiny_config(
        plane_readout=readout, compressed_channels=CHANNELS, readout_dim=DIM, readout_latents=LATENTS
    )


EXPECTED_DIM = {
    "keypoint_features": CHANNELS * (3 + DIM),
    "latent_queries": LATENTS * DIM,
    "bev_conv": DIM * 8,
}


@pytest.mark.parametrize("readout", sorted(EXPECTED_DIM))
def test_readout_trains_depends_on_images_and_round_trips(readout, tmp_path):
    policy = OmniDPolicy(readout_config(readout)).train()
    assert policy.model.ofg.out_dim == EXPECTED_DIM[readout]
    images = torch.rand(2, 1, 4, 3, SIZE, SIZE)
    pix_T_cam, cam_T_world = policy.camera_matrices(2, (SIZE, SIZE))
    condition, _ = policy.model.encode_images(images, pix_T_cam, cam_T_world)
    assert condition.shape == (2, 1, EXPECTED_DIM[readout])
    assert condition.std(dim=0).sum() > 0  # two different images give two conditions
    loss, _ = policy.forward(random_batch(policy.config))
    loss.backward()
    readout_grads = [p.grad.abs().sum() for p in policy.model.ofg.readout.parameters()]
    assert all(g > 0 for g in readout_grads)
    assert policy.model.backbone.stem[0].weight.grad.abs().sum() > 0
    policy.eval()
    obs = {k: torch.rand(1, *ft.shape) for k, ft in policy.config.image_features.items()}
    obs["observation.state"] = torch.randn(1, STATE_DIM)
    noise = torch.randn(1, policy.config.horizon, 10, generator=torch.Generator().manual_seed(1))
    expected = policy.select_action(obs, noise=noise)
    policy.save_pretrained(tmp_path)
    loaded = OmniDPolicy.from_pretrained(tmp_path).eval()
    assert loaded.config.plane_readout == readout
    assert torch.equal(loaded.select_action(obs, noise=noise), expected)


def test_presence_tells_a_strong_peak_from_a_weak_one_the_keypoint_cannot():
    readout = KeypointFeatureReadout(d_model=4, channels=1, feature_dim=2)
    plane_xy = torch.tensor([[-1.0, 0.0], [0.0, 0.0], [1.0, 0.0]])
    plane = torch.zeros(1, 3, 4)
    weak = torch.tensor([[[0.0], [1.0], [0.0]]])
    strong = weak + 5.0  # the same shape shifted up: the same softmax, hence the same keypoint
    out_weak, out_strong = readout(plane, weak, plane_xy), readout(plane, strong, plane_xy)
    assert torch.allclose(out_weak[:, :2], out_strong[:, :2])
    assert out_strong[0, -1].item() == pytest.approx(out_weak[0, -1].item() + 5.0)


def test_latent_queries_and_bev_conv_see_where_things_are():
    torch.manual_seed(0)
    plane_xy = torch.stack(
        torch.meshgrid(torch.linspace(-1, 1, 4), torch.linspace(-1, 1, 4), indexing="ij"), -1
    )
    plane_xy = plane_xy.reshape(16, 2)
    plane = torch.zeros(2, 16, 8)
    plane[0, 0], plane[1, 15] = 1.0, 1.0  # the same feature in opposite corners
    latents = LatentQueryReadout(d_model=8, num_heads=2, num_latents=2, feature_dim=3)
    assert not torch.allclose(*latents(plane, None, plane_xy))
    compressed = plane[..., :1]
    conv = BEVConvReadout(channels=1, plane_shape=(4, 4), feature_dim=2)
    assert conv(plane, compressed, plane_xy).shape == (2, 16)
    assert not torch.allclose(*conv(plane, compressed, plane_xy))


def test_readout_options_are_validated():
    with pytest.raises(ValueError, match="`plane_readout`: expected one of"):
        tiny_config(plane_readout="mean")
    with pytest.raises(ValueError, match="`readout_latents`: expected a positive integer"):
        tiny_config(readout_latents=0)
