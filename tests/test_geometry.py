"""Camera geometry: hand-computed pinhole values, masks, round trips."""

import pytest
import torch
import torch.nn.functional as F

from lerobot_omnid.geometry import (
    FeatureVolume,
    apply_transform,
    axis_angle_to_matrix,
    camera_centers_world,
    clamp_to_feature_cells,
    crop_intrinsics,
    crop_theta,
    look_at,
    perturb_extrinsics,
    pixels_to_feature_grid,
    pixels_to_grid,
    point_seen_on_plane,
    project_to_grid,
    project_to_pixels,
    rotation_warp_grid,
    translate_world,
)

K = torch.tensor([[100.0, 0.0, 50.0], [0.0, 120.0, 40.0], [0.0, 0.0, 1.0]])


def test_projection_matches_hand_computed_pinhole():
    xyz_cam = torch.tensor([[0.1, 0.2, 2.0], [0.0, 0.0, 1.0], [-0.5, 0.25, 0.5]])
    uv, in_front = project_to_pixels(K, xyz_cam)
    expected = torch.tensor(
        [[100 * 0.05 + 50, 120 * 0.1 + 40], [50.0, 40.0], [100 * -1 + 50, 120 * 0.5 + 40]]
    )
    assert torch.allclose(uv, expected)
    assert in_front.all()


def test_world_to_pixels_through_extrinsics():
    # Camera 2 m above the origin looking straight down, image x along world -y... checked by hand:
    cam_T_world = torch.tensor(
        [[0.0, -1.0, 0.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 2.0], [0.0, 0.0, 0.0, 1.0]]
    )
    xyz_world = torch.tensor([[0.2, 0.1, 0.0]])  # -> cam (-0.1, -0.2, 2.0)
    xyz_cam = apply_transform(cam_T_world, xyz_world)
    assert torch.allclose(xyz_cam, torch.tensor([[-0.1, -0.2, 2.0]]))
    uv, _ = project_to_pixels(K, xyz_cam)
    assert torch.allclose(uv, torch.tensor([[50 - 5.0, 40 - 12.0]]))


def test_transform_round_trip():
    cam_T_world = look_at(torch.tensor([1.0, 0.5, 0.8]), torch.tensor([0.4, 0.0, 0.0]))
    xyz = torch.rand(7, 3)
    back = apply_transform(torch.linalg.inv(cam_T_world), apply_transform(cam_T_world, xyz))
    assert torch.allclose(back, xyz, atol=1e-6)


def test_visibility_mask_behind_and_outside():
    cam_T_world = torch.eye(4)[None, None]
    pix_T_cam = K[None, None]
    pts = torch.tensor(
        [
            [0.0, 0.0, 1.0],  # image point (50, 40): visible
            [0.0, 0.0, -1.0],  # behind the camera
            [5.0, 0.0, 1.0],  # u = 550: right of a 100-wide image
            [0.0, -1.0, 1.0],  # v = -80: above the image
            [0.0, 0.0, 0.0],  # on the camera centre
        ]
    )
    grid, visible = project_to_grid(pix_T_cam, cam_T_world, pts, image_hw=(80, 100))
    assert visible[0, 0].tolist() == [True, False, False, False, False]
    assert torch.isfinite(grid).all()


def test_pixels_to_grid_edges_and_centre():
    uv = torch.tensor([[-0.5, -0.5], [99.5, 79.5], [49.5, 39.5]])
    grid = pixels_to_grid(uv, (80, 100))
    assert torch.allclose(grid, torch.tensor([[-1.0, -1.0], [1.0, 1.0], [0.0, 0.0]]))


def test_grid_sample_reads_the_projected_pixel():
    image = torch.zeros(1, 1, 80, 100)
    image[0, 0, 33, 71] = 1.0  # v = 33, u = 71
    grid = pixels_to_grid(torch.tensor([[71.0, 33.0]]), (80, 100)).view(1, 1, 1, 2)
    assert F.grid_sample(image, grid, align_corners=False).item() == pytest.approx(1.0)


def test_look_at_centres_target_and_round_trips_eye():
    eye, target = torch.tensor([1.2, -0.4, 0.7]), torch.tensor([0.5, 0.1, 0.0])
    cam_T_world = look_at(eye, target)
    assert torch.allclose(camera_centers_world(cam_T_world), eye, atol=1e-6)
    uv, in_front = project_to_pixels(K, apply_transform(cam_T_world, target[None]))
    assert in_front.all() and torch.allclose(uv, K[:2, 2][None], atol=1e-4)
    # World up appears up in the image: a point above the target has a smaller v.
    uv_up, _ = project_to_pixels(K, apply_transform(cam_T_world, (target + torch.tensor([0, 0, 0.1]))[None]))
    assert uv_up[0, 1] < uv[0, 1]


@pytest.mark.parametrize("pillar_axis", ["x", "y", "z"])
def test_feature_volume_anchors(pillar_axis):
    volume = FeatureVolume(
        bounds=((0.0, 1.0), (-0.5, 0.5), (0.0, 0.4)), shape=(4, 2, 8), pillar_axis=pillar_axis
    )
    anchors = volume.anchors_world()
    p = "xyz".index(pillar_axis)
    assert anchors.shape == (volume.num_queries, volume.shape[p], 3)
    assert volume.num_queries * volume.num_anchors == 4 * 2 * 8
    # Anchors of one pillar differ only along the pillar axis, by one cell each.
    steps = anchors[0, 1:] - anchors[0, :-1]
    cell = (volume.bounds[p][1] - volume.bounds[p][0]) / volume.shape[p]
    expected = torch.zeros(3)
    expected[p] = cell
    assert torch.allclose(steps, expected.expand_as(steps), atol=1e-6)
    lo = torch.tensor([b[0] for b in volume.bounds])
    hi = torch.tensor([b[1] for b in volume.bounds])
    assert ((anchors > lo) & (anchors < hi)).all()
    coords = volume.plane_coords_normalized()
    assert coords.shape == (volume.num_queries, 3) and coords.abs().max() <= 1


def test_feature_volume_rejects_bad_input():
    with pytest.raises(ValueError, match="pillar_axis"):
        FeatureVolume(bounds=((0, 1), (0, 1), (0, 1)), shape=(2, 2, 2), pillar_axis="w")
    with pytest.raises(ValueError, match="min < max"):
        FeatureVolume(bounds=((1, 0), (0, 1), (0, 1)), shape=(2, 2, 2))


@pytest.mark.parametrize(("width", "stride"), [(100, 32), (96, 8), (720, 32), (128, 16)])
def test_pixels_to_feature_grid_reads_the_cell_centred_on_the_pixel(width, stride):
    cells = -(-width // stride)  # a ResNet's ceil(W / stride) cells, whatever W
    feature = torch.arange(cells, dtype=torch.float32).view(1, 1, 1, cells).expand(1, 1, 3, cells)
    uv_pix = torch.tensor([[stride * j + 0.0, stride * 1.0] for j in range(cells)])
    grid = pixels_to_feature_grid(uv_pix, (3, cells), stride, 0.0).view(1, 1, cells, 2)
    sampled = F.grid_sample(feature, grid, align_corners=False).view(-1)
    assert torch.allclose(sampled, torch.arange(cells, dtype=torch.float32), atol=1e-5)


def test_crop_theta_and_intrinsics_move_a_pixel_together():
    image = torch.zeros(1, 1, 60, 80)
    image[0, 0, 20, 50] = 1.0  # v = 20, u = 50
    box = torch.tensor([[0.25, 0.1, 0.5, 0.5]])  # left, top, width, height
    grid = F.affine_grid(crop_theta(box), [1, 1, 60, 80], align_corners=False)
    cropped = F.grid_sample(image, grid, align_corners=False)[0, 0]
    ys, xs = torch.meshgrid(torch.arange(60.0), torch.arange(80.0), indexing="ij")
    centroid = torch.stack([(cropped * xs).sum(), (cropped * ys).sum()]) / cropped.sum()
    K = torch.tensor([[70.0, 0.0, 39.5], [0.0, 70.0, 29.5], [0.0, 0.0, 1.0]])
    xyz_cam = torch.tensor([[(50 - 39.5) / 70, (20 - 29.5) / 70, 1.0]])
    uv, _ = project_to_pixels(crop_intrinsics(K[None], box, (60, 80))[0], xyz_cam)
    assert torch.allclose(uv[0], centroid, atol=1e-4)
    full = torch.tensor([[0.0, 0.0, 1.0, 1.0]])
    assert torch.allclose(crop_intrinsics(K[None], full, (60, 80))[0], K)


def test_clamp_to_feature_cells_moves_only_the_image_margin_beyond_the_cells():
    # 96 x 64 image, stride 32, offset 0: cells centred at u = 0, 32, 64 and v = 0, 32.
    uv = torch.tensor(
        [[-0.5, -0.5], [10.0, 20.0], [70.0, 40.0], [95.5, 63.5], [96.0, 30.0], [-3.0, 70.0], [80.0, 70.0]]
    )
    clamped = clamp_to_feature_cells(uv, (64, 96), (2, 3), stride=32, offset=0.0)
    expected = torch.tensor(
        [[0.0, 0.0], [10.0, 20.0], [64.0, 32.0], [64.0, 32.0], [96.0, 30.0], [-3.0, 70.0], [64.0, 70.0]]
    )
    assert torch.equal(clamped, expected)  # outside the image (per axis): untouched
    # An offset moves the span of the cells with it.
    shifted = clamp_to_feature_cells(torch.tensor([[1.0, 90.0]]), (96, 96), (3, 3), stride=32, offset=4.0)
    assert torch.equal(shifted, torch.tensor([[4.0, 68.0]]))


def test_translate_world_sees_the_moved_point_where_the_old_one_was():
    cam_T_world = look_at(torch.tensor([1.0, -0.5, 0.8]), torch.tensor([0.5, 0.0, 0.0]))
    points = torch.tensor([[0.5, 0.0, 0.0], [0.6, 0.1, 0.05], [0.4, -0.2, 0.2]])
    shift = torch.tensor([0.03, -0.07, 0.0])
    moved = translate_world(cam_T_world, shift)
    assert torch.allclose(
        apply_transform(moved, points + shift), apply_transform(cam_T_world, points), atol=1e-6
    )
    # The camera itself moved by the shift: its centre in the world is the old one plus the shift.
    assert torch.allclose(camera_centers_world(moved), camera_centers_world(cam_T_world) + shift, atol=1e-6)
    batch = translate_world(cam_T_world.expand(2, 3, 4, 4), torch.zeros(2, 3, 3))  # (..., 4, 4) batches
    assert torch.allclose(batch, cam_T_world.expand(2, 3, 4, 4))


def test_point_seen_on_plane_undoes_a_believed_translation():
    """A camera believed 3 cm further along world x (its centre only) samples, for ``point``, the pixel where
    the true camera sees ``point`` 3 cm back; with the true pose it sees ``point`` itself."""
    true = look_at(
        torch.tensor([1.0, -0.5, 0.8], dtype=torch.float64),
        torch.tensor([0.5, 0.0, 0.0], dtype=torch.float64),
    )
    shift = torch.tensor([0.03, 0.0, 0.0], dtype=torch.float64)
    believed = translate_world(true, shift)  # the camera believed moved by +shift
    assert torch.allclose(camera_centers_world(believed), camera_centers_world(true) + shift)
    point = torch.tensor([0.55, 0.1, 0.035], dtype=torch.float64)
    K64 = K.to(torch.float64)
    assert torch.allclose(point_seen_on_plane(K64, true, true, point), point, atol=1e-9)
    assert torch.allclose(point_seen_on_plane(K64, believed, true, point), point - shift, atol=1e-9)


def blob(uv: torch.Tensor, hw: tuple[int, int], sigma: float = 1.5) -> torch.Tensor:
    """(1, 1, H, W) image of a Gaussian spot centred on pixel ``uv`` (pixel centres at integers)."""
    v, u = torch.meshgrid(torch.arange(hw[0]), torch.arange(hw[1]), indexing="ij")
    return torch.exp(-((u - uv[0]) ** 2 + (v - uv[1]) ** 2) / (2 * sigma**2))[None, None].float()


def spot(image: torch.Tensor) -> torch.Tensor:
    """Intensity-weighted centre (u, v) of a (1, 1, H, W) image."""
    v, u = torch.meshgrid(torch.arange(image.shape[-2]), torch.arange(image.shape[-1]), indexing="ij")
    w = image[0, 0] / image.sum()
    return torch.stack([(w * u).sum(), (w * v).sum()])


@pytest.mark.parametrize(("image_hw", "calibrated_hw"), [((64, 64), (64, 64)), ((48, 64), (96, 128))])
def test_rotation_warp_shows_a_point_where_the_turned_calibration_projects_it(image_hw, calibrated_hw):
    """Warping a camera's image by ``rotation_warp_grid`` and turning its extrinsics by the same rotation
    keep them consistent: a world point's spot moves to where the turned calibration projects it (a sign
    or transpose error moves it the other way); at any image size the calibration's is a resize of."""
    h, w = calibrated_hw
    K_cal = torch.tensor([[0.8 * w, 0.0, (w - 1) / 2], [0.0, 0.8 * w, (h - 1) / 2], [0.0, 0.0, 1.0]])
    cam_T_world = look_at(torch.tensor([0.0, -1.0, 1.0]), torch.tensor([0.0, 0.0, 0.0]))
    point = torch.tensor([[0.05, 0.03, 0.02]])
    rotation = axis_angle_to_matrix(F.normalize(torch.tensor([0.3, -0.8, 0.5]), dim=0), torch.tensor(0.1))
    turned = perturb_extrinsics(cam_T_world, rotation, torch.zeros(3))
    scale = torch.tensor([image_hw[1] / w, image_hw[0] / h])

    def seen(T: torch.Tensor) -> torch.Tensor:  # the point's pixel in the image of size image_hw
        uv, _ = project_to_pixels(K_cal, apply_transform(T, point))
        return (uv[0] + 0.5) * scale - 0.5

    before, after = seen(cam_T_world), seen(turned)
    assert (after - before).norm() > 3  # the turn moves the point by several pixels
    image = blob(before, image_hw)
    grid = rotation_warp_grid(K_cal, rotation, image_hw, calibrated_hw)
    assert grid.shape == (*image_hw, 2)
    warped = F.grid_sample(image, grid[None], mode="bilinear", padding_mode="zeros", align_corners=False)
    assert torch.allclose(spot(warped), after, atol=0.15)
    still = rotation_warp_grid(K_cal, torch.eye(3), image_hw, calibrated_hw)
    identity = F.grid_sample(image, still[None], mode="bilinear", padding_mode="zeros", align_corners=False)
    assert torch.allclose(identity, image, atol=1e-5)
