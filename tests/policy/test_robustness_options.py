"""Training-time robustness options: calibration noise (the perturbation maths) and camera dropout."""

import math

import pytest
import torch
from omnid_testing import random_batch, tiny_config

from lerobot_omnid.geometry import (
    axis_angle_to_matrix,
    camera_centers_world,
    perturb_extrinsics,
    perturb_intrinsics,
    random_unit_vectors,
)
from lerobot_omnid.policy import omni_feature_generator
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy, camera_dropout_mask
from lerobot_omnid.policy.omni_feature_generator import OmniFeatureGenerator


def rotation_angle_deg(R: torch.Tensor) -> torch.Tensor:
    return torch.rad2deg(torch.arccos(((R.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1, 1)))


def test_rotation_has_the_requested_angle_and_is_proper():
    axes = random_unit_vectors((50,), generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    angles = torch.linspace(0.0, 3.0, 50, dtype=torch.float64)
    R = axis_angle_to_matrix(axes, angles)
    assert torch.allclose(
        R @ R.transpose(-1, -2), torch.eye(3, dtype=torch.float64).expand(50, 3, 3), atol=1e-12
    )
    assert torch.allclose(torch.linalg.det(R), torch.ones(50, dtype=torch.float64))
    assert torch.allclose(torch.deg2rad(rotation_angle_deg(R)), angles, atol=1e-6)
    assert torch.allclose((R @ axes[..., None])[..., 0], axes, atol=1e-12)  # the axis is fixed


def test_perturbation_of_size_zero_changes_nothing_and_sizes_are_exact():
    cam_T_world = torch.tensor(tiny_config().camera_calibration["observation.images.cam_b"]["T_cam_world"])
    K = torch.tensor(tiny_config().camera_calibration["observation.images.cam_b"]["K"])
    same = perturb_extrinsics(cam_T_world, torch.eye(3), torch.zeros(3))
    assert torch.equal(same, cam_T_world)
    assert torch.equal(perturb_intrinsics(K, torch.tensor(1.0), torch.zeros(2)), K)
    # 2 cm in the camera frame moves the optical centre by 2 cm; a pure rotation keeps it.
    moved = perturb_extrinsics(cam_T_world, torch.eye(3), torch.tensor([0.0, 0.012, 0.016]))
    shift = camera_centers_world(moved) - camera_centers_world(cam_T_world)
    assert shift.norm().item() == pytest.approx(0.02, abs=1e-6)
    turned = perturb_extrinsics(
        cam_T_world, axis_angle_to_matrix(torch.tensor([0.0, 1.0, 0.0]), torch.tensor(0.1)), torch.zeros(3)
    )
    assert torch.allclose(camera_centers_world(turned), camera_centers_world(cam_T_world), atol=1e-6)
    doubled = perturb_intrinsics(K, torch.tensor(2.0), torch.tensor([3.0, -1.0]))
    assert doubled[0, 0] == 2 * K[0, 0] and doubled[1, 1] == 2 * K[1, 1]
    assert doubled[0, 2] == K[0, 2] + 3 and doubled[1, 2] == K[1, 2] - 1


NOISE = {
    "calibration_noise_rotation_deg": 2.0,
    "calibration_noise_translation_mm": 20.0,
    "calibration_noise_focal_pct": 2.0,
    "calibration_noise_principal_px": 1.0,
}


def test_calibration_noise_is_per_sample_seeded_and_off_by_default():
    policy = OmniDPolicy(tiny_config(**NOISE))
    pix_T_cam, cam_T_world = policy.camera_matrices(3, (64, 64))
    torch.manual_seed(5)
    K1, T1 = policy._calibration_noise(pix_T_cam, cam_T_world)
    torch.manual_seed(5)
    K2, T2 = policy._calibration_noise(pix_T_cam, cam_T_world)
    assert torch.equal(K1, K2) and torch.equal(T1, T2)  # seeded by torch's RNG (LeRobot seeds it)
    assert not torch.allclose(T1[0], T1[1]) and not torch.allclose(K1[0], K1[1])  # per sample
    assert not torch.allclose(T1[0, 0], T1[0, 1])  # per camera
    # Per frame (B, T, S, ...): every observation step of a sample gets the same perturbation.
    K5, T5 = policy._calibration_noise(
        pix_T_cam[:, None].expand(-1, 2, -1, -1, -1), cam_T_world[:, None].expand(-1, 2, -1, -1, -1)
    )
    assert torch.equal(T5[:, 0], T5[:, 1]) and torch.equal(K5[:, 0], K5[:, 1])
    # Off by default: the matrices pass through, and training uses it only in train mode.
    quiet = OmniDPolicy(tiny_config())
    K0, T0 = quiet._calibration_noise(pix_T_cam, cam_T_world)
    assert torch.equal(K0, pix_T_cam) and torch.equal(T0, cam_T_world)
    rotation = T1[..., :3, :3] @ cam_T_world[..., :3, :3].transpose(-1, -2)
    assert 0 < rotation_angle_deg(rotation).mean() < 10


def test_camera_dropout_keeps_one_camera_and_training_stays_finite():
    mask = camera_dropout_mask(500, 4, 0.9, torch.device("cpu"))
    assert mask.any(dim=1).all()
    assert 0.05 < mask.float().mean() < 0.5  # most cameras dropped at p = 0.9
    assert not camera_dropout_mask(10, 4, 0.0, torch.device("cpu")).logical_not().any()
    policy = OmniDPolicy(tiny_config(camera_dropout=0.5, **NOISE)).train()
    loss, _ = policy.forward(random_batch(policy.config))
    assert torch.isfinite(loss)
    loss.backward()


def test_single_camera_rate_keeps_exactly_one_camera_drawn_uniformly():
    cpu = torch.device("cpu")
    torch.manual_seed(0)
    every = camera_dropout_mask(4000, 4, 0.0, cpu, single_rate=1.0)
    assert (every.sum(dim=1) == 1).all()
    share = every.float().mean(dim=0)  # each camera the one kept about a quarter of the time
    assert ((share - 0.25).abs() < 0.03).all(), share
    half = camera_dropout_mask(4000, 4, 0.0, cpu, single_rate=0.5).sum(dim=1)
    assert abs((half == 1).float().mean() - 0.5) < 0.03 and set(half.tolist()) == {1, 4}
    assert not camera_dropout_mask(10, 4, 0.0, cpu, single_rate=0.0).logical_not().any()


def test_single_camera_training_lifts_from_the_kept_camera_alone(monkeypatch, tmp_path):
    """With every sample on one camera, the plane the head gets is that camera's plane alone; the option
    survives save and load like every other field."""
    policy = OmniDPolicy(tiny_config(single_camera_rate=1.0)).train()
    masks = []
    original = policy.model.global_condition

    def spy(*args, **kwargs):
        masks.append(args[4] if len(args) > 4 else kwargs.get("camera_mask"))
        return original(*args, **kwargs)

    monkeypatch.setattr(policy.model, "global_condition", spy)
    loss, _ = policy.forward(random_batch(policy.config))
    assert torch.isfinite(loss)
    assert masks and (masks[0].sum(dim=1) == 1).all()
    policy.save_pretrained(tmp_path)
    assert OmniDPolicy.from_pretrained(tmp_path).config.single_camera_rate == 1.0
    with pytest.raises(ValueError, match=r"`single_camera_rate`: expected a share in \[0, 1\], got 1.5"):
        tiny_config(single_camera_rate=1.5)


def check_dropped_cameras_are_left_out_of_the_plane(policy: OmniDPolicy) -> None:
    """Two samples with different cameras dropped (B in sample 0, D in sample 1): each sample's plane must
    be the plane of its kept cameras alone, the attention renormalised over them."""
    images = torch.rand(2, 1, 4, 3, 64, 64)
    pix_T_cam, cam_T_world = policy.camera_matrices(2, (64, 64))
    mask = torch.tensor([[False, True, True, True], [True, True, False, True]])
    with torch.no_grad():
        _, dropped = policy.model.encode_images(images, pix_T_cam, cam_T_world, mask)
        for b in range(2):
            kept = mask[b]
            _, alone = policy.model.encode_images(
                images[b : b + 1, :, kept], pix_T_cam[b : b + 1, kept], cam_T_world[b : b + 1, kept]
            )
            assert torch.allclose(dropped.plane[b], alone.plane[0], atol=1e-5), f"sample {b}"
        _, full = policy.model.encode_images(images, pix_T_cam, cam_T_world)
    assert not torch.allclose(full.plane, dropped.plane, atol=1e-3)
    assert not dropped.attention_weights[0, 0].any() and not dropped.attention_weights[1, 2].any()


def test_dropped_cameras_are_left_out_of_the_plane():
    check_dropped_cameras_are_left_out_of_the_plane(OmniDPolicy(tiny_config()).eval())


@pytest.mark.parametrize("fault", ["mask after the softmax", "mask ignored", "sample 0's mask for all"])
def test_the_dropout_check_catches_a_faulty_mask(monkeypatch, fault):
    """The check above can fail: a mask applied after the softmax (the dropped camera's samples zeroed,
    the others' weights not renormalised), a mask ignored, or sample 0's mask used for the batch."""
    forward = OmniFeatureGenerator.forward
    sampling = omni_feature_generator.multi_camera_deformable_sampling

    def faulty(self, feature_maps, pix_T_cam, cam_T_world, image_hw, camera_mask=None):
        if camera_mask is not None and fault == "mask after the softmax":
            mask = camera_mask[:, :, None, None, None]  # B, S -> B, S, Q, heads, N

            def zeroed_after_softmax(values, grid, weights, **kwargs):
                return sampling(values, grid, weights * mask, **kwargs)

            with monkeypatch.context() as m:
                m.setattr(omni_feature_generator, "multi_camera_deformable_sampling", zeroed_after_softmax)
                return forward(self, feature_maps, pix_T_cam, cam_T_world, image_hw, None)
        if camera_mask is not None:
            camera_mask = None if fault == "mask ignored" else camera_mask[:1].expand_as(camera_mask)
        return forward(self, feature_maps, pix_T_cam, cam_T_world, image_hw, camera_mask)

    monkeypatch.setattr(OmniFeatureGenerator, "forward", faulty)
    with pytest.raises(AssertionError):
        check_dropped_cameras_are_left_out_of_the_plane(OmniDPolicy(tiny_config()).eval())


def test_noise_options_are_validated():
    with pytest.raises(
        ValueError, match="`calibration_noise_rotation_deg`: expected a standard deviation >= 0"
    ):
        tiny_config(calibration_noise_rotation_deg=-1.0)
    with pytest.raises(ValueError, match=r"`camera_dropout`: expected a probability in \[0, 1\)"):
        tiny_config(camera_dropout=1.0)
    assert math.isclose(tiny_config().camera_dropout, 0.0)
