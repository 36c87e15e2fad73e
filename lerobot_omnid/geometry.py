"""Camera geometry and the feature volume, as small pure batched functions.

Frames are named in every identifier: ``cam_T_world`` maps world points into the OpenCV camera frame,
``pix_T_cam`` is the intrinsics ``K``; point sets carry their frame (``xyz_world``, ``xyz_cam``,
``uv_pix``). Pixel centres are at integer coordinates (OpenCV).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from lerobot_omnid.cli import check_choice

AXES = ("x", "y", "z")
DEPTH_EPS = 1e-3  # metres; points closer than this to the camera plane count as behind it.
PAPER_VOLUME_BOUNDS = ((0.0, 1.152), (-0.64, 0.64), (0.0, 0.768))
"""The paper's feature volume in the robot base frame, metres: (x, y, z) (min, max) pairs."""


@dataclass(frozen=True)
class FeatureVolume:
    """Axis-aligned box in the world (robot base) frame, divided into cells, folded into pillars.

    The query plane spans the two axes other than ``pillar_axis``; every plane cell owns one pillar of
    ``shape[pillar_axis]`` anchor points (the cell centres along the pillar axis).

    Args:
        bounds: ((x_min, x_max), (y_min, y_max), (z_min, z_max)) in metres.
        shape: number of cells along (x, y, z).
        pillar_axis: "x", "y" or "z": the axis folded into pillars.
    """

    bounds: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    shape: tuple[int, int, int]
    pillar_axis: str = "z"

    def __post_init__(self) -> None:
        check_choice("pillar_axis", self.pillar_axis, AXES)
        if len(self.bounds) != 3 or any(len(b) != 2 or not b[0] < b[1] for b in self.bounds):
            raise ValueError(f"bounds must be three (min, max) pairs with min < max, got {self.bounds}")
        if len(self.shape) != 3 or any(int(n) < 1 for n in self.shape):
            raise ValueError(f"shape must be three positive cell counts, got {self.shape}")

    @property
    def plane_axes(self) -> tuple[int, int]:
        """Indices of the two axes spanning the query plane, in x, y, z order."""
        p = AXES.index(self.pillar_axis)
        return tuple(i for i in range(3) if i != p)  # type: ignore[return-value]

    @property
    def plane_shape(self) -> tuple[int, int]:
        a, b = self.plane_axes
        return self.shape[a], self.shape[b]

    @property
    def num_queries(self) -> int:
        a, b = self.plane_shape
        return a * b

    @property
    def num_anchors(self) -> int:
        return self.shape[AXES.index(self.pillar_axis)]

    def cell_centers(self, axis: int) -> Tensor:
        """(n,) centres of the cells along one axis, in metres."""
        lo, hi = self.bounds[axis]
        n = self.shape[axis]
        step = (hi - lo) / n
        return lo + step * (torch.arange(n, dtype=torch.float64) + 0.5)

    def anchors_world(self) -> Tensor:
        """(Q, A, 3) world xyz of every anchor; Q = plane cells in row-major plane order, A = pillar cells."""
        a, b = self.plane_axes
        p = AXES.index(self.pillar_axis)
        ca, cb, cp = self.cell_centers(a), self.cell_centers(b), self.cell_centers(p)
        grid_a, grid_b, grid_p = torch.meshgrid(ca, cb, cp, indexing="ij")  # (Na, Nb, A) each
        xyz = torch.zeros(*grid_a.shape, 3, dtype=torch.float64)
        xyz[..., a], xyz[..., b], xyz[..., p] = grid_a, grid_b, grid_p
        return xyz.reshape(-1, self.num_anchors, 3).float()

    def plane_coords_normalized(self) -> Tensor:
        """(Q, 3) pillar centres mapped to [-1, 1]^3 within the volume (for positional embeddings)."""
        lo = torch.tensor([b[0] for b in self.bounds])
        hi = torch.tensor([b[1] for b in self.bounds])
        centres = self.anchors_world().mean(dim=1)
        return 2 * (centres - lo) / (hi - lo) - 1


def apply_transform(T_b_a: Tensor, xyz_a: Tensor) -> Tensor:
    """Map points from frame a to frame b.

    Args:
        T_b_a: (..., 4, 4) rigid transform.
        xyz_a: (..., N, 3) points in frame a (leading dims broadcast with ``T_b_a``'s).
    Returns:
        (..., N, 3) points in frame b.
    """
    return xyz_a @ T_b_a[..., :3, :3].transpose(-1, -2) + T_b_a[..., None, :3, 3]


def project_to_pixels(pix_T_cam: Tensor, xyz_cam: Tensor) -> tuple[Tensor, Tensor]:
    """Pinhole projection with a guarded perspective divide.

    Args:
        pix_T_cam: (..., 3, 3) intrinsics K.
        xyz_cam: (..., N, 3) points in the OpenCV camera frame.
    Returns:
        uv_pix: (..., N, 2) pixel coordinates (meaningless where ``in_front`` is False).
        in_front: (..., N) bool, depth above ``DEPTH_EPS``.
    """
    depth = xyz_cam[..., 2:3]
    in_front = depth[..., 0] > DEPTH_EPS
    uvw = xyz_cam @ pix_T_cam.transpose(-1, -2)
    uv_pix = uvw[..., :2] / depth.clamp(min=DEPTH_EPS)
    return uv_pix, in_front


def pixels_to_grid(uv_pix: Tensor, image_hw: tuple[int, int]) -> Tensor:
    """Pixel coordinates -> ``grid_sample`` coordinates in [-1, 1] (``align_corners=False``).

    With pixel centres at integers, the image spans [-0.5, W - 0.5] in u, mapped to [-1, 1].
    """
    h, w = image_hw
    scale = uv_pix.new_tensor([2.0 / w, 2.0 / h])
    return (uv_pix + 0.5) * scale - 1.0


def grid_to_pixels(grid: Tensor, image_hw: tuple[int, int]) -> Tensor:
    """Inverse of :func:`pixels_to_grid`: (..., 2) ``grid_sample`` coordinates -> (..., 2) pixels."""
    h, w = image_hw
    return (grid + 1.0) * grid.new_tensor([w / 2.0, h / 2.0]) - 0.5


def pixels_to_feature_grid(uv_pix: Tensor, feature_hw: tuple[int, int], stride: int, offset: float) -> Tensor:
    """Image pixels -> ``grid_sample`` coordinates (``align_corners=False``) on a feature map.

    Cell (i, j) of the map is centred on pixel (u, v) = (stride * j + offset, stride * i + offset) of the
    image it was computed from (see ``backbone.feature_cell_centres``), whatever the image size: a map of
    ``ceil(W / stride)`` cells need not span exactly the image, so the image's own grid coordinates would
    misplace samples by up to a cell near the far edge.

    Args:
        uv_pix: (..., 2) pixel coordinates in the image.
        feature_hw: (h, w) cells of the feature map.
        stride, offset: where the cells are, in pixels.
    """
    h, w = feature_hw
    cells = (uv_pix - offset) / stride
    return (cells + 0.5) * uv_pix.new_tensor([2.0 / w, 2.0 / h]) - 1.0


def clamp_to_feature_cells(
    uv_pix: Tensor, image_hw: tuple[int, int], feature_hw: tuple[int, int], stride: int, offset: float
) -> Tensor:
    """Pixels inside the image moved onto the span of the feature cells' centres, per axis.

    The last cell of a map of ``ceil(W / stride)`` cells is centred at ``stride * (w - 1) + offset``, up to
    a stride short of the image's far edge: a point of the image beyond it would be sampled mostly from the
    feature map's zero padding (a fade to nothing at the right and bottom edges) while it counts as visible
    with full attention weight. Clamped, it reads the nearest cell, which covers it. Coordinates outside
    the image are left as they are (zero padding: nothing is seen there).

    Args:
        uv_pix: (..., 2) pixel coordinates (u, v) in the image of ``image_hw``.
        feature_hw: (h, w) cells of the feature map computed from that image.
        stride, offset: where the cells are, in pixels (cell ``j`` centred on ``stride * j + offset``).
    """
    (h, w), (fh, fw) = image_hw, feature_hw
    first = uv_pix.new_tensor([offset, offset])
    last = uv_pix.new_tensor([stride * (fw - 1) + offset, stride * (fh - 1) + offset])
    inside = (uv_pix >= -0.5) & (uv_pix <= uv_pix.new_tensor([w - 0.5, h - 0.5]))
    return torch.where(inside, torch.minimum(torch.maximum(uv_pix, first), last), uv_pix)


def project_to_grid(
    pix_T_cam: Tensor, cam_T_world: Tensor, xyz_world: Tensor, image_hw: tuple[int, int]
) -> tuple[Tensor, Tensor]:
    """Project world points into images as ``grid_sample`` coordinates, with a visibility mask.

    Args:
        pix_T_cam: (B, S, 3, 3) intrinsics per sample and camera, for images of ``image_hw``.
        cam_T_world: (B, S, 4, 4) extrinsics per sample and camera.
        xyz_world: (N, 3) points shared by the batch.
        image_hw: (height, width) the intrinsics refer to.
    Returns:
        grid: (B, S, N, 2) coordinates in [-1, 1] where visible.
        visible: (B, S, N) bool: in front of the camera and inside the image.
    """
    xyz_cam = apply_transform(cam_T_world, xyz_world)  # B, S, N, 3
    uv_pix, in_front = project_to_pixels(pix_T_cam, xyz_cam)
    grid = pixels_to_grid(uv_pix, image_hw)
    inside = (grid.abs() <= 1.0).all(dim=-1)
    return grid, in_front & inside


def camera_centers_world(cam_T_world: Tensor) -> Tensor:
    """(..., 4, 4) extrinsics -> (..., 3) camera optical centres in the world frame (-R^T t)."""
    R = cam_T_world[..., :3, :3]
    t = cam_T_world[..., :3, 3:]
    return -(R.transpose(-1, -2) @ t)[..., 0]


def look_at(eye_world: Tensor, target_world: Tensor, up_world: Tensor | None = None) -> Tensor:
    """``cam_T_world`` (4, 4) of an OpenCV camera at ``eye_world`` looking at ``target_world``.

    The image's v axis (down) is the projection of ``-up_world`` (default world z), so the world's up
    points up in the image. ``eye``/``target``: (3,) tensors in the world frame.
    """
    up = up_world if up_world is not None else eye_world.new_tensor([0.0, 0.0, 1.0])
    z = target_world - eye_world
    z = z / z.norm()
    x = torch.linalg.cross(z, up)
    x = x / x.norm()
    y = torch.linalg.cross(z, x)
    cam_T_world = torch.eye(4, dtype=eye_world.dtype)
    cam_T_world[:3, :3] = torch.stack([x, y, z])  # rows: camera axes in world coordinates
    cam_T_world[:3, 3] = -cam_T_world[:3, :3] @ eye_world
    return cam_T_world


def resize_intrinsics(pix_T_cam: Tensor, from_hw: tuple[int, int], to_hw: tuple[int, int]) -> Tensor:
    """Intrinsics after resizing a whole image from ``from_hw`` to ``to_hw``: pixel centres stay at integers,
    ``u' = (u + 0.5) * sx - 0.5``. A resize is the crop of :func:`crop_intrinsics` whose box starts at the
    corner and spans ``from / to`` of the output. ``pix_T_cam``: (..., 3, 3)."""
    box = pix_T_cam.new_tensor([0.0, 0.0, from_hw[1] / to_hw[1], from_hw[0] / to_hw[0]])
    return crop_intrinsics(pix_T_cam, box.expand(*pix_T_cam.shape[:-2], 4), to_hw)


def crop_theta(box: Tensor) -> Tensor:
    """``F.affine_grid`` matrices that cut ``box`` out of an image and stretch it over the whole output.

    Args:
        box: (..., 4) crops as fractions of the image, (left, top, width, height), edges of the image at
            0 and 1 (``align_corners=False``).
    Returns:
        (..., 2, 3) theta mapping output grid coordinates to input grid coordinates.
    """
    left, top, width, height = box.unbind(-1)
    zero = torch.zeros_like(left)
    row_x = torch.stack([width, zero, 2 * left + width - 1], dim=-1)
    row_y = torch.stack([zero, height, 2 * top + height - 1], dim=-1)
    return torch.stack([row_x, row_y], dim=-2)


def crop_intrinsics(pix_T_cam: Tensor, box: Tensor, image_hw: tuple[int, int]) -> Tensor:
    """Intrinsics of the image that :func:`crop_theta` makes: the crop resized back to ``image_hw``.

    A pixel centre ``u`` of the crop (edges at ``left * W`` and ``(left + width) * W``) moves to
    ``(u + 0.5 - left * W) / width - 0.5``.

    Args:
        pix_T_cam: (..., 3, 3) intrinsics for images of ``image_hw``.
        box: (..., 4) (left, top, width, height) as fractions of the image.
    """
    h, w = image_hw
    left, top, width, height = box.unbind(-1)
    scale = torch.stack([1 / width, 1 / height], dim=-1)  # ..., 2
    shift = torch.stack([left * w, top * h], dim=-1)
    K = pix_T_cam.clone()
    K[..., :2, :] = pix_T_cam[..., :2, :] * scale[..., :, None]
    K[..., :2, 2] = (pix_T_cam[..., :2, 2] + 0.5 - shift) * scale - 0.5
    return K


def axis_angle_to_matrix(axis: Tensor, angle: Tensor) -> Tensor:
    """Rodrigues: rotation by ``angle`` (radians, (...,)) about the unit ``axis`` (..., 3) -> (..., 3, 3)."""
    x, y, z = axis.unbind(-1)
    zero = torch.zeros_like(x)
    skew = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], dim=-1).unflatten(-1, (3, 3))
    eye = torch.eye(3, dtype=axis.dtype, device=axis.device).expand_as(skew)
    s, c = angle.sin()[..., None, None], angle.cos()[..., None, None]
    return eye + s * skew + (1 - c) * (skew @ skew)


def random_unit_vectors(shape: tuple[int, ...], generator: torch.Generator | None = None, **like) -> Tensor:
    """(*shape, 3) directions uniform on the sphere."""
    v = torch.randn(*shape, 3, generator=generator, **like)
    return v / v.norm(dim=-1, keepdim=True).clamp(min=1e-12)


def perturb_extrinsics(cam_T_world: Tensor, rotation: Tensor, translation_m: Tensor) -> Tensor:
    """A camera believed elsewhere: ``[R | t] @ cam_T_world``, i.e. turned by ``rotation`` about its own
    optical centre and then moved by ``translation_m`` in its own frame (the centre moves by that length).

    Args:
        cam_T_world: (..., 4, 4).
        rotation: (..., 3, 3).
        translation_m: (..., 3) metres, in the camera frame.
    """
    delta = torch.eye(4, dtype=cam_T_world.dtype, device=cam_T_world.device).expand_as(cam_T_world).clone()
    delta[..., :3, :3] = rotation
    delta[..., :3, 3] = translation_m
    return delta @ cam_T_world


def rotation_warp_grid(
    pix_T_cam: Tensor, rotation: Tensor, image_hw: tuple[int, int], calibrated_hw: tuple[int, int]
) -> Tensor:
    """``grid_sample`` coordinates (``align_corners=False``) that make, from a camera's image, the image it
    would take turned by ``rotation`` about its optical centre: the pure-rotation homography ``K R^T K^-1``
    needs no depth, so the turned view is exact where the unturned one saw (outside: off the grid, > 1).
    The turned camera's extrinsics are ``perturb_extrinsics(cam_T_world, rotation, 0)``.

    Args:
        pix_T_cam: (..., 3, 3) K for images of ``calibrated_hw``.
        rotation: (..., 3, 3) the turn: a point's coordinates in the turned camera's frame are ``rotation``
            times those in the unturned one's.
        image_hw: (H, W) of the images to warp, a uniform resize of ``calibrated_hw``.
    Returns:
        (..., H, W, 2) for each pixel of the turned image, where to read the unturned one.
    """
    h, w = image_hw
    like = {"dtype": pix_T_cam.dtype, "device": pix_T_cam.device}
    v, u = torch.meshgrid(torch.arange(h, **like), torch.arange(w, **like), indexing="ij")
    grid = pixels_to_grid(torch.stack([u, v], dim=-1), image_hw)  # H, W, 2: the output pixels
    uv = grid_to_pixels(grid, calibrated_hw)  # in the calibration's pixel units
    pixel = torch.cat([uv, torch.ones_like(uv[..., :1])], dim=-1)  # H, W, 3
    source_from_target = pix_T_cam @ rotation.transpose(-1, -2) @ torch.linalg.inv(pix_T_cam)  # ..., 3, 3
    ray = pixel @ source_from_target[..., None, :, :].transpose(-1, -2)  # ..., H, W, 3
    source, in_front = project_to_pixels(torch.eye(3, **like), ray.flatten(-3, -2))
    source = pixels_to_grid(source, calibrated_hw).unflatten(-2, (h, w))
    return torch.where(in_front.unflatten(-1, (h, w))[..., None], source, torch.full_like(source, 2.0))


def translate_world(cam_T_world: Tensor, shift_m: Tensor) -> Tensor:
    """The same cameras in a world where everything, cameras included, moved by ``shift_m``: a point
    ``p + shift_m`` is seen where ``p`` was, i.e. ``cam_T_world @ T(-shift_m)``; the images stay true.

    Args:
        cam_T_world: (..., 4, 4).
        shift_m: (..., 3) metres, world frame.
    """
    back = torch.eye(4, dtype=cam_T_world.dtype, device=cam_T_world.device).expand_as(cam_T_world).clone()
    back[..., :3, 3] = -shift_m
    return cam_T_world @ back


def point_seen_on_plane(
    pix_T_cam: Tensor, believed_T_world: Tensor, true_T_world: Tensor, point: Tensor
) -> Tensor:
    """Where a camera really looks when a policy believing it at ``believed_T_world`` samples ``point``: the
    believed projection's pixel cast back through the true pose onto the horizontal plane through ``point``.
    An object there lands in the policy's volume at ``point``; with the true pose, the result is ``point``.

    Args:
        pix_T_cam: (..., 3, 3) K.
        believed_T_world, true_T_world: (..., 4, 4) extrinsics (the calibration used, the camera's own).
        point: (..., 3) world point, metres.
    Returns:
        (..., 3) world point on the plane ``z = point.z`` (the ray's intersection; undefined for a ray
        parallel to the plane).
    """
    uv, _ = project_to_pixels(pix_T_cam, apply_transform(believed_T_world, point[..., None, :]))  # ..., 1, 2
    pixel = torch.cat([uv[..., 0, :], torch.ones_like(uv[..., 0, :1])], dim=-1)  # ..., 3
    ray_cam = (torch.linalg.inv(pix_T_cam) @ pixel[..., None])[..., 0]
    ray_world = (true_T_world[..., :3, :3].transpose(-1, -2) @ ray_cam[..., None])[..., 0]
    centre = camera_centers_world(true_T_world)
    depth = (point[..., 2:] - centre[..., 2:]) / ray_world[..., 2:]
    return centre + depth * ray_world


def perturb_intrinsics(pix_T_cam: Tensor, focal_scale: Tensor, principal_shift_px: Tensor) -> Tensor:
    """``fx, fy`` (and the skew) times ``focal_scale`` (...,), the principal point moved by
    ``principal_shift_px`` (..., 2). ``pix_T_cam``: (..., 3, 3)."""
    K = pix_T_cam.clone()
    K[..., 0, :2] = pix_T_cam[..., 0, :2] * focal_scale[..., None]
    K[..., 1, 1] = pix_T_cam[..., 1, 1] * focal_scale
    K[..., :2, 2] = pix_T_cam[..., :2, 2] + principal_shift_px
    return K
