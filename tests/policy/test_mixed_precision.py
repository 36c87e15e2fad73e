"""Mixed precision: the camera geometry runs in full precision under autocast.

In bf16 a projection matmul keeps 8 bits of mantissa: on the paper's volume with 480-pixel images the
anchors' pixels move by several pixels and anchors near the image edges flip between visible and not.
"""

import torch
from omnid_testing import SYNTHETIC_EYES, random_batch, synthetic_calibration, tiny_config

from lerobot_omnid.geometry import PAPER_VOLUME_BOUNDS
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy
from lerobot_omnid.policy.omni_feature_generator import OmniFeatureGenerator, camera_geometry

IMAGE_SIZE = 480
CAMS = tuple(SYNTHETIC_EYES)  # five cameras around the table


def paper_geometry_inputs() -> tuple[OmniFeatureGenerator, torch.Tensor, torch.Tensor, torch.Tensor]:
    """A one-layer OFG on the paper's volume, random feature maps of 480-pixel images, the cameras' K and
    T_cam_world."""
    config = tiny_config(
        CAMS,
        size=IMAGE_SIZE,
        volume_bounds=PAPER_VOLUME_BOUNDS,
        volume_shape=(64, 16, 64),
        d_model=16,
        num_heads=2,
        num_layers=1,
        use_self_attention=False,
    )
    ofg = OmniFeatureGenerator(config, in_channels=8, feature_stride=32, feature_offset=0.0).eval()
    calibs = [synthetic_calibration(cam, IMAGE_SIZE) for cam in CAMS]
    pix_T_cam = torch.tensor([c["K"] for c in calibs], dtype=torch.float32)[None]
    cam_T_world = torch.tensor([c["T_cam_world"] for c in calibs], dtype=torch.float32)[None]
    features = torch.rand(1, len(CAMS), 8, IMAGE_SIZE // 32, IMAGE_SIZE // 32)
    return ofg, features, pix_T_cam, cam_T_world


def test_projections_under_bf16_autocast_equal_the_fp32_ones():
    ofg, features, pix_T_cam, cam_T_world = paper_geometry_inputs()
    reference = camera_geometry(ofg.anchors_world, pix_T_cam, cam_T_world, (IMAGE_SIZE, IMAGE_SIZE))
    with torch.no_grad(), torch.autocast("cpu", dtype=torch.bfloat16):
        out = ofg(features, pix_T_cam, cam_T_world, (IMAGE_SIZE, IMAGE_SIZE))
    assert out.geometry.anchor_grid.dtype == torch.float32
    assert torch.equal(out.geometry.anchor_grid, reference.anchor_grid)
    assert torch.equal(out.geometry.anchor_visible, reference.anchor_visible)
    assert torch.equal(out.geometry.descriptor, reference.descriptor)
    # Where the samples are taken stays in full precision too (offsets start at zero: the anchors).
    assert out.sampling_grid.dtype == torch.float32


def test_bf16_autocast_would_move_the_projections():
    """The check above has something to catch: the same projection computed under autocast is off."""
    ofg, _, pix_T_cam, cam_T_world = paper_geometry_inputs()
    reference = camera_geometry(ofg.anchors_world, pix_T_cam, cam_T_world, (IMAGE_SIZE, IMAGE_SIZE))
    with torch.autocast("cpu", dtype=torch.bfloat16):
        low = camera_geometry(ofg.anchors_world, pix_T_cam, cam_T_world, (IMAGE_SIZE, IMAGE_SIZE))
    pixels_off = (low.anchor_grid.float() - reference.anchor_grid).abs().max() * IMAGE_SIZE / 2
    assert pixels_off > 1.0
    assert (low.anchor_visible != reference.anchor_visible).sum() > 0


def test_a_training_step_under_bf16_autocast_is_finite():
    policy = OmniDPolicy(
        tiny_config(calibration_noise_rotation_deg=1.0, calibration_noise_translation_mm=5.0)
    ).train()
    with torch.autocast("cpu", dtype=torch.bfloat16):
        loss, _ = policy.forward(random_batch(policy.config))
    assert torch.isfinite(loss)
    loss.backward()
