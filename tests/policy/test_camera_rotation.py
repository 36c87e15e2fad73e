"""``camera_rotation_deg``: each training sample's cameras turned about their optical centres, images and
extrinsics together (the warp's geometry itself: tests/test_geometry.py)."""

import math

import pytest
import torch
import torch.nn.functional as F
from omnid_testing import random_batch, tiny_config

from lerobot_omnid.geometry import axis_angle_to_matrix, random_unit_vectors, rotation_warp_grid
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy


def turns(B: int, S: int, degrees: float) -> torch.Tensor:
    axes = random_unit_vectors((B, S), generator=torch.Generator().manual_seed(0))
    return axis_angle_to_matrix(axes, torch.full((B, S), math.radians(degrees)))


@pytest.mark.parametrize("per_frame", [False, True])
def test_each_camera_is_warped_and_turned_by_its_own_rotation(per_frame):
    policy = OmniDPolicy(tiny_config(camera_rotation_deg=5.0))
    B, T, S, H = 3, 2, 4, 64
    images = torch.rand(B, T, S, 3, H, H, generator=torch.Generator().manual_seed(1))
    K, cam_T_world = policy.camera_matrices(B, (H, H))
    if per_frame:  # every frame's own calibration: (B, T, S, ...)
        K, cam_T_world = (m[:, None].expand(B, T, *m.shape[1:]) for m in (K, cam_T_world))
    rotation = turns(B, S, 4.0)
    warped, turned = policy._rotate_cameras(images, K, cam_T_world, rotation)
    assert warped.shape == images.shape and turned.shape == cam_T_world.shape
    for b, t, s in ((2, 0, 1), (1, 1, 3), (0, 1, 0)):
        Ks = K[b, t, s] if per_frame else K[b, s]
        grid = rotation_warp_grid(Ks, rotation[b, s], (H, H), (H, H))
        expected = F.grid_sample(images[b, t, s][None], grid[None], padding_mode="zeros", align_corners=False)
        # 1e-4: the batched grid differs from the single one by float32 rounding (up to 1.1e-5 measured);
        # another camera's rotation moves pixels by O(0.1).
        assert torch.allclose(warped[b, t, s], expected[0], atol=1e-4)
        T_bs = cam_T_world[b, t, s] if per_frame else cam_T_world[b, s]
        new = turned[b, t, s] if per_frame else turned[b, s]
        assert torch.allclose(new[:3, :3], rotation[b, s] @ T_bs[:3, :3], atol=1e-6)
        assert torch.allclose(new[:3, 3], rotation[b, s] @ T_bs[:3, 3], atol=1e-6)  # the centre stays


def test_training_draws_a_turn_per_sample_and_camera_up_to_the_angle(tmp_path):
    policy = OmniDPolicy(tiny_config(camera_rotation_deg=5.0)).train()
    B, T, S, H = 8, 2, 4, 64
    images = torch.rand(B, T, S, 3, H, H)
    K, cam_T_world = policy.camera_matrices(B, (H, H))
    torch.manual_seed(3)
    _, turned = policy._rotate_cameras(images, K, cam_T_world)
    rotation = turned[..., :3, :3] @ cam_T_world[..., :3, :3].transpose(-1, -2)
    angle = torch.rad2deg(torch.arccos(((rotation.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1, 1)))
    assert (angle <= 5.0 + 1e-3).all() and angle.std() > 0.5  # per sample and camera, up to the angle
    loss, _ = policy.forward(random_batch(policy.config))
    assert torch.isfinite(loss)
    loss.backward()
    policy.save_pretrained(tmp_path)
    assert OmniDPolicy.from_pretrained(tmp_path).config.camera_rotation_deg == 5.0


def test_off_by_default_and_refused_out_of_range():
    policy = OmniDPolicy(tiny_config())
    seen = {}
    policy._rotate_cameras = lambda *args: seen.setdefault("called", args)
    policy.train()
    policy.forward(random_batch(policy.config))
    assert not seen
    for bad in (-1.0, 90.0):
        with pytest.raises(ValueError, match=r"`camera_rotation_deg`: expected an angle in \[0, 90\)"):
            tiny_config(camera_rotation_deg=bad)
