"""End to end, geometry only: a bright blob at a known 3D point, seen by every camera, must make the OFG's
plane peak at that point's cell.

The backbone is replaced by a fixed local filter (a Gaussian blur with the backbone's stride, whose cells
sit where :func:`feature_cell_centres` says) and the OFG's cross-attention keeps zero offsets, uniform
weights and identity projections, so the plane is the mean of the filtered images sampled at the projected
anchors. Anything that misplaces samples (a half-cell offset, a feature map stretched over an image whose
size is not a multiple of the stride, intrinsics not rescaled for a camera of another size) moves the peak.
"""

import math

import pytest
import torch
from omnid_testing import STATE_DIM, tiny_config
from torch import nn

from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.geometry import FeatureVolume, apply_transform, look_at, pixels_to_grid, project_to_pixels
from lerobot_omnid.policy.backbone import feature_cell_centres
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy
from lerobot_omnid.policy.omni_feature_generator import (
    CAMERA_GEOMETRY_DIM,
    CameraCrossAttention,
    CameraGeometry,
    camera_geometry,
)

BLOB_WORLD = (0.47, 0.03, 0.11)  # metres, robot base frame
CAMERA_EYES = ((1.25, 0.1, 0.7), (0.45, 0.85, 0.55), (0.4, -0.8, 0.75), (-0.3, 0.05, 0.9))
BLOB_SIGMA_PX = 1.5
PLANE_CELLS = 7  # per plane axis, the blob's cell in the middle
PILLAR_ANCHORS = 5
CELL_FOOTPRINTS = 1.5  # a plane cell spans this many feature cells at the blob's distance


def pinhole(image_hw: tuple[int, int], eye) -> CameraCalibration:
    """A 90-degree (horizontal) camera at ``eye`` looking at the blob."""
    h, w = image_hw
    f = w / 2
    cam_T_world = look_at(
        torch.tensor(eye, dtype=torch.float64), torch.tensor(BLOB_WORLD, dtype=torch.float64)
    )
    K = [[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]]
    return CameraCalibration.from_dict({"K": K, "T_cam_world": cam_T_world.tolist(), "image_size": [h, w]})


def blob_image(calib: CameraCalibration) -> torch.Tensor:
    """(3, H, W) black image with a Gaussian blob painted where ``calib`` projects the blob."""
    h, w = calib.image_size
    xyz_cam = apply_transform(torch.tensor(calib.T_cam_world), torch.tensor([BLOB_WORLD]))
    ((u, v),) = project_to_pixels(torch.tensor(calib.K), xyz_cam)[0].tolist()
    ys, xs = torch.meshgrid(
        torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij"
    )
    blob = torch.exp(-((xs - u) ** 2 + (ys - v) ** 2) / (2 * BLOB_SIGMA_PX**2))
    return blob.expand(3, h, w).clone()


class GaussianFilter(nn.Module):
    """A fixed local filter with the backbone's stride: cell j centred on pixel ``stride * j``."""

    def __init__(self, stride: int) -> None:
        super().__init__()
        radius = stride
        taps = torch.arange(-radius, radius + 1, dtype=torch.float32)
        g = torch.exp(-(taps**2) / (2 * (stride / 2) ** 2))
        kernel = g[:, None] * g[None, :]
        self.conv = nn.Conv2d(3, 1, 2 * radius + 1, stride=stride, padding=radius, bias=False)
        with torch.no_grad():
            self.conv.weight.copy_((kernel / kernel.sum() / 3).expand(1, 3, -1, -1))

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.conv(images)


def volume_around_blob(pillar_axis: str, cell: float) -> FeatureVolume:
    """PLANE_CELLS x PLANE_CELLS plane cells of side ``cell`` with the blob at the centre of the middle one,
    pillars of PILLAR_ANCHORS anchors, one of them at the blob."""
    bounds, shape = [], []
    for axis, centre in zip("xyz", BLOB_WORLD, strict=True):
        n = PILLAR_ANCHORS if axis == pillar_axis else PLANE_CELLS
        bounds.append((centre - n * cell / 2, centre + n * cell / 2))
        shape.append(n)
    return FeatureVolume(tuple(bounds), tuple(shape), pillar_axis)


def uniform_cross_attention(volume: FeatureVolume, stride: int, offset: float) -> CameraCrossAttention:
    config = tiny_config(d_model=1, num_heads=1, num_points=1, ffn_dim=4)
    attention = CameraCrossAttention(config, volume.num_anchors, stride, offset).eval()
    with torch.no_grad():
        for linear in (attention.value_proj, attention.output_proj):
            linear.weight.fill_(1.0)
            linear.bias.zero_()
        for linear in (attention.sampling_offsets, attention.attention_logits):
            linear.weight.zero_()
            linear.bias.zero_()
    return attention


def plane_peak(
    images: torch.Tensor, pix_T_cam, cam_T_world, image_hw, volume, stride, seen_by_all: bool = False
) -> tuple[int, int]:
    """images (S, 3, H, W) -> the (row, col) plane cell where the uniform OFG's plane is largest; among the
    cells every camera sees with ``seen_by_all`` (a cell seen by one camera is as bright as any cell that
    camera's ray through the blob crosses)."""
    stride_, offset = feature_cell_centres([GaussianFilter(stride).conv])
    assert (stride_, offset) == (stride, 0.0)
    features = GaussianFilter(stride)(images)[None]  # 1, S, 1, h, w
    geometry = camera_geometry(volume.anchors_world(), pix_T_cam, cam_T_world, image_hw)
    attention = uniform_cross_attention(volume, stride, offset)
    with torch.no_grad():
        plane, _, _ = attention(torch.zeros(1, volume.num_queries, 1), features, geometry)
    values = plane[0, :, 0]
    if seen_by_all:
        every_camera = geometry.anchor_visible[0].any(dim=-1).all(dim=0)  # Q
        values = values.masked_fill(~every_camera, -torch.inf)
    index = int(values.argmax())
    return divmod(index, volume.plane_shape[1])


def footprint(calib: CameraCalibration, stride: int) -> float:
    """Metres that one feature cell spans at the blob's distance from the camera."""
    centre = -torch.tensor(calib.T_cam_world)[:3, :3].T @ torch.tensor(calib.T_cam_world)[:3, 3]
    distance = float(torch.linalg.norm(torch.tensor(BLOB_WORLD) - centre))
    return stride * distance / calib.K[0][0]


CASES = [
    (8, (96, 96)),
    (8, (100, 100)),
    (16, (128, 128)),
    (8, (480, 480)),
    (16, (480, 480)),
    (32, (480, 480)),
]
CASES += [(16, (480, 640)), (32, (480, 640)), (32, (720, 720))]


@pytest.mark.parametrize("pillar_axis", ["x", "y", "z"])
@pytest.mark.parametrize(("stride", "image_hw"), CASES, ids=[f"s{s}-{h}x{w}" for s, (h, w) in CASES])
def test_plane_peaks_at_the_blob(pillar_axis, stride, image_hw):
    calibs = [pinhole(image_hw, eye) for eye in CAMERA_EYES]
    cell = CELL_FOOTPRINTS * max(footprint(c, stride) for c in calibs)
    volume = volume_around_blob(pillar_axis, cell)
    images = torch.stack([blob_image(c) for c in calibs])
    pix_T_cam = torch.tensor([c.K for c in calibs], dtype=torch.float32)[None]
    cam_T_world = torch.tensor([c.T_cam_world for c in calibs], dtype=torch.float32)[None]
    assert plane_peak(images, pix_T_cam, cam_T_world, image_hw, volume, stride) == (3, 3)


def test_cameras_of_different_sizes_in_one_rig():
    """Cameras at 480x640, 96x96, 128x128 and 100x100 through the policy's own path: each image resized to
    ``resize_shape`` and each camera's K for that size, then fused."""
    sizes = [(480, 640), (96, 96), (128, 128), (100, 100)]
    calibs = [pinhole(hw, eye) for hw, eye in zip(sizes, CAMERA_EYES, strict=True)]
    cams = ("cam_a", "cam_b", "cam_c", "cam_d")
    keys = [f"observation.images.{c}" for c in cams]
    config = tiny_config(
        cams,
        resize_shape=(192, 192),
        images_stretched=True,  # the 640-wide camera is squeezed into the square input on purpose
        camera_calibration={k: c.to_dict() for k, c in zip(keys, calibs, strict=True)},
        backbone_layer=2,
    )
    policy = OmniDPolicy(config)
    batch = {k: blob_image(c)[None] for k, c in zip(keys, calibs, strict=True)}
    batch["observation.state"] = torch.zeros(1, STATE_DIM)
    images = policy._stack_inputs(batch, time_dim=False)["observation.images"][0]  # S, 3, 192, 192
    pix_T_cam, cam_T_world = policy.camera_matrices(1, (192, 192))
    stride = 8
    resized = [c.resized((192, 192)) for c in calibs]
    cell = CELL_FOOTPRINTS * max(footprint(c, stride) for c in resized)
    volume = volume_around_blob("z", cell)
    assert plane_peak(images, pix_T_cam, cam_T_world, (192, 192), volume, stride) == (3, 3)


def test_another_aspect_ratio_is_refused_unless_stretched():
    calib = pinhole((480, 640), CAMERA_EYES[0])
    key = "observation.images.cam_b"
    config = tiny_config(
        ("cam_b",), size=64, camera_calibration={key: calib.to_dict()}, resize_shape=(64, 64)
    )
    policy = OmniDPolicy(config).eval()
    obs = {key: torch.rand(1, 3, 64, 64), "observation.state": torch.zeros(1, STATE_DIM)}
    with pytest.raises(
        ValueError, match=r"cam_b: images of 64x64 .* calibration of 480x640.*images_stretched"
    ):
        policy.select_action(obs)
    config = tiny_config(
        ("cam_b",),
        size=64,
        camera_calibration={key: calib.to_dict()},
        resize_shape=(64, 64),
        images_stretched=True,
    )
    assert OmniDPolicy(config).eval().select_action(obs).shape[0] == 1
    # The same aspect at another scale is a plain resize.
    obs[key] = torch.rand(1, 3, 48, 64)
    policy = OmniDPolicy(tiny_config(("cam_b",), size=64, camera_calibration={key: calib.to_dict()})).eval()
    assert policy.select_action(obs).shape[0] == 1


def test_cameras_of_different_sizes_need_resize_shape():
    policy = OmniDPolicy(tiny_config(("cam_b", "cam_c"))).eval()
    obs = {
        "observation.images.cam_b": torch.rand(1, 3, 64, 64),
        "observation.images.cam_c": torch.rand(1, 3, 32, 32),
        "observation.state": torch.zeros(1, STATE_DIM),
    }
    with pytest.raises(ValueError, match=r"one image size unless `resize_shape`.*cam_c 32x32"):
        policy.select_action(obs)


def test_random_crop_moves_images_and_intrinsics_together():
    """With the crop augmentation, a blob's pixel in the cropped image is where the updated K projects it."""
    calib = pinhole((64, 64), CAMERA_EYES[0])
    key = "observation.images.cam_b"
    config = tiny_config(
        ("cam_b",), size=64, camera_calibration={key: calib.to_dict()}, random_crop_min_scale=0.5
    )
    policy = OmniDPolicy(config).train()
    images = blob_image(calib)[None, None, None]  # B=1, T=1, S=1, 3, H, W
    pix_T_cam, _ = policy.camera_matrices(1, (64, 64))
    torch.manual_seed(3)
    cropped, K = policy._random_crop(images, pix_T_cam)
    assert not torch.equal(K, pix_T_cam)
    xyz_cam = apply_transform(
        torch.tensor(calib.T_cam_world, dtype=torch.float32), torch.tensor([BLOB_WORLD])
    )
    ((u, v),) = project_to_pixels(K[0, 0], xyz_cam)[0].tolist()
    heat = cropped[0, 0, 0, 0]
    row, col = divmod(int(heat.argmax()), heat.shape[1])
    assert math.hypot(col - u, row - v) <= 1.0
    # Off in evaluation.
    policy.eval()
    assert torch.isfinite(policy.forward(random_training_batch(policy))[0])


def random_training_batch(policy: OmniDPolicy) -> dict:
    T = policy.config.n_obs_steps
    batch = {k: torch.rand(2, T, *ft.shape) for k, ft in policy.config.image_features.items()}
    batch["observation.state"] = torch.randn(2, T, STATE_DIM)
    batch["action"] = torch.randn(2, policy.config.horizon, 10)
    batch["action_is_pad"] = torch.zeros(2, policy.config.horizon, dtype=torch.bool)
    return batch


def test_feature_cell_centres_of_a_strided_chain():
    layers = [nn.Conv2d(3, 3, 7, stride=2, padding=3), nn.MaxPool2d(3, 2, 1), nn.Conv2d(3, 3, 3, 2, 0)]
    # conv: 2j + 3 - 3; pool: 2j + 1 - 1; conv without padding: 2j + 1 -> 8j + 4
    assert feature_cell_centres(layers) == (8, 4.0)


def edge_pinhole(image_hw: tuple[int, int], eye, edge: str, margin_px: float) -> CameraCalibration:
    """``pinhole`` with its principal point moved so that the blob (on the optical axis) lands
    ``margin_px`` inside one edge of the image ("left", "right", "top" or "bottom")."""
    calib = pinhole(image_hw, eye).to_dict()
    h, w = image_hw
    u, v = {
        "left": (margin_px, (h - 1) / 2),
        "right": (w - 1 - margin_px, (h - 1) / 2),
        "top": ((w - 1) / 2, margin_px),
        "bottom": ((w - 1) / 2, h - 1 - margin_px),
    }[edge]
    calib["K"][0][2], calib["K"][1][2] = u, v
    return CameraCalibration.from_dict(calib)


EDGE_CASES = [(8, (96, 96)), (8, (100, 100)), (16, (128, 128)), (16, (480, 480)), (32, (480, 640))]


@pytest.mark.parametrize("edge", ["left", "right", "top", "bottom"])
@pytest.mark.parametrize(
    ("stride", "image_hw"), EDGE_CASES, ids=[f"s{s}-{h}x{w}" for s, (h, w) in EDGE_CASES]
)
def test_plane_peaks_at_a_blob_near_the_edge(edge, stride, image_hw):
    """Within the last half-stride of the image the nearest feature cell is read, not the map's padding:
    a blob there must still peak at its cell among the cells every camera sees (a sampler that fades to
    zero at the edge moves the peak inwards)."""
    calibs = [edge_pinhole(image_hw, eye, edge, margin_px=stride / 4) for eye in CAMERA_EYES]
    cell = CELL_FOOTPRINTS * max(footprint(c, stride) for c in calibs)
    volume = volume_around_blob("z", cell)
    images = torch.stack([blob_image(c) for c in calibs])
    pix_T_cam = torch.tensor([c.K for c in calibs], dtype=torch.float32)[None]
    cam_T_world = torch.tensor([c.T_cam_world for c in calibs], dtype=torch.float32)[None]
    assert plane_peak(images, pix_T_cam, cam_T_world, image_hw, volume, stride, seen_by_all=True) == (3, 3)


@pytest.mark.parametrize("edge", ["left", "right", "top", "bottom"])
@pytest.mark.parametrize(
    ("stride", "image_hw"), EDGE_CASES, ids=[f"s{s}-{h}x{w}" for s, (h, w) in EDGE_CASES]
)
def test_a_blob_near_the_edge_is_read_at_the_strength_the_map_has_it(edge, stride, image_hw):
    """One camera, one anchor at the blob: the OFG reads the blob's feature at (nearly) the strongest cell
    of the map, the cell next to it, wherever it is in the image. A sampler whose last half-stride reads
    the map's zero padding reads a fraction of it at the right and bottom edges."""
    volume = FeatureVolume(tuple((c - 0.005, c + 0.005) for c in BLOB_WORLD), (1, 1, 1))
    attention = uniform_cross_attention(volume, stride, 0.0)
    for eye in CAMERA_EYES:
        calib = edge_pinhole(image_hw, eye, edge, margin_px=stride / 4)
        features = GaussianFilter(stride)(blob_image(calib)[None])[None]  # 1, 1, 1, h, w
        geometry = camera_geometry(
            volume.anchors_world(),
            torch.tensor([[calib.K]], dtype=torch.float32),
            torch.tensor([[calib.T_cam_world]], dtype=torch.float32),
            image_hw,
        )
        assert geometry.anchor_visible.all()
        with torch.no_grad():
            plane, _, _ = attention(torch.zeros(1, 1, 1), features, geometry)
        assert plane.item() >= 0.75 * features.max().item()


@pytest.mark.parametrize("u", [0.0, 48.0, 80.0, 95.0])
def test_a_constant_map_reads_the_same_up_to_the_image_edge(u):
    """A constant feature map of a 96-pixel image (stride 32: cells centred at 0, 32, 64) reads its value
    anywhere inside the image, the last half-stride included; outside the image it reads nothing."""
    stride, image_hw = 32, (96, 96)
    volume = FeatureVolume(((0.0, 1.0), (0.0, 1.0), (0.0, 1.0)), (1, 1, 1))
    attention = uniform_cross_attention(volume, stride, 0.0)
    features = torch.ones(1, 1, 1, 3, 3)  # B, S, D, h, w
    uv_pix = torch.tensor([[u, 47.5], [47.5, u], [96.5, 47.5]])  # along u, along v, outside
    grid = pixels_to_grid(uv_pix, image_hw)  # 3, 2
    geometry = CameraGeometry(
        anchor_grid=grid.view(1, 1, 3, 1, 2),  # B, S, Q, A, 2: three queries of one anchor
        anchor_visible=torch.ones(1, 1, 3, 1, dtype=torch.bool),
        descriptor=torch.zeros(1, 1, 3, CAMERA_GEOMETRY_DIM),
        image_hw=image_hw,
    )
    with torch.no_grad():
        plane, _, _ = attention(torch.zeros(1, 3, 1), features, geometry)
    assert plane[0, :2, 0].tolist() == pytest.approx([1.0, 1.0], abs=1e-5)
    assert plane[0, 2, 0].item() == pytest.approx(0.0, abs=1e-5)
