"""What ``omnid-viz`` draws: pure functions from the OFG output to pixels and maps; one matplotlib frame.

Shape legend: S cameras, Q plane queries, A anchors per pillar, P points per anchor, D channels,
N points drawn, H W image. The tensors come from
:class:`~lerobot_omnid.policy.omni_feature_generator.OFGOutput` of ONE fused observation step (its batch
dimension already indexed away).

Grid coordinates are ``grid_sample``'s ([-1, 1] spans the image, ``align_corners=False``); they do not
depend on the image size, so the OFG's anchors and samples (at the backbone's input size) land on the
displayed image of any size once converted with :func:`grid_to_pixels`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import torch
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from matplotlib.patheffects import withStroke
from torch import Tensor

from lerobot_omnid.geometry import AXES, FeatureVolume, grid_to_pixels, project_to_grid
from lerobot_omnid.policy.omni_feature_generator import OFGOutput

ANCHOR_CMAP = "viridis"  # anchors coloured by height
WEIGHT_CMAP = "autumn"  # the chosen query's samples coloured by attention weight
BEV_CMAP = "inferno"  # a map without negative values, from its minimum to its maximum
BEV_SIGNED_CMAP = "RdBu_r"  # a signed map (one compressed channel), centred on 0
OBJECT_COLOR = "cyan"
LABEL_SPACING = 0.15  # object names closer than this share of the volume's extent to a named one are left out
QUERY_COLOR = "lime"
OUTLINE = [withStroke(linewidth=2.0, foreground="black")]  # keeps light marks readable on any image
PANEL_INCHES = 3.2  # side of one camera panel
BEV_SCALE = 1.3  # height of the BEV row relative to the camera row
ANCHOR_SIZE = 5.0  # points^2: marker area of an anchor
SAMPLE_MAX_SIZE = 60.0  # points^2: marker area of the heaviest sample
SAMPLE_MIN_SIZE = 4.0
VIDEO_CODECS = ("libx264", "mpeg4")  # the first one PyAV has is used


def project_points(
    pix_T_cam: Tensor, cam_T_world: Tensor, xyz_world: Tensor, image_hw: tuple[int, int]
) -> tuple[Tensor, Tensor]:
    """World points -> pixels of every camera, by the projection the OFG uses for its anchors.

    Args:
        pix_T_cam: (S, 3, 3) intrinsics for images of ``image_hw``.
        cam_T_world: (S, 4, 4) extrinsics.
        xyz_world: (N, 3) points in the world (robot base) frame, metres.
    Returns:
        uv_pix (S, N, 2) and visible (S, N): in front of the camera and inside the image.
    """
    grid, visible = project_to_grid(pix_T_cam[None], cam_T_world[None], xyz_world, image_hw)
    return grid_to_pixels(grid[0], image_hw), visible[0]


def anchor_lattice(volume: FeatureVolume, max_points: int) -> Tensor:
    """(Q, A) bool: a regular sub-lattice of the anchors (same stride along x, y, z) of at most
    ``max_points`` points, so that dense paper-size volumes stay readable."""
    stride = max(1, int(np.ceil((np.prod(volume.shape) / max(max_points, 1)) ** (1 / 3))))
    keep = [
        torch.arange(n) % stride == stride // 2 if n > stride else torch.arange(n) == n // 2
        for n in volume.shape
    ]
    a, b = volume.plane_axes
    p = AXES.index(volume.pillar_axis)
    mask = keep[a][:, None, None] & keep[b][None, :, None] & keep[p][None, None, :]  # Na, Nb, A
    return mask.reshape(volume.num_queries, volume.num_anchors)


def attention_share(weights: Tensor) -> Tensor:
    """(S, ...) attention weights -> (S,) share of the total weight each camera receives (sums to 1;
    all zeros when no camera sees anything)."""
    per_camera = weights.flatten(1).sum(dim=1)
    total = per_camera.sum()
    return per_camera / total if total > 0 else torch.zeros_like(per_camera)


def bev_heatmap(compressed: Tensor, plane_shape: tuple[int, int]) -> Tensor:
    """The channel-compressed plane (what the diffusion head's image condition is read from) as a map.

    Args:
        compressed: (Q, c) one step's ``OFGOutput.compressed``: c channels per query.
    Returns:
        (Na, Nb), rows along the first plane axis: the value itself when c = 1, else its L2 norm over c.
    """
    pooled = compressed[:, 0] if compressed.shape[1] == 1 else compressed.norm(dim=-1)
    return pooled.reshape(plane_shape)


def query_index(volume: FeatureVolume, xyz_world: np.ndarray) -> tuple[int, int] | None:
    """Plane cell (i, j) whose pillar contains ``xyz_world`` (3,), or None outside the volume's plane."""
    index = []
    for axis in volume.plane_axes:
        lo, hi = volume.bounds[axis]
        cell = int(np.floor((xyz_world[axis] - lo) / (hi - lo) * volume.shape[axis]))
        if not 0 <= cell < volume.shape[axis]:
            return None
        index.append(cell)
    return index[0], index[1]


def query_samples(
    sampling_grid: Tensor, weights: Tensor, query: int, image_hw: tuple[int, int]
) -> tuple[Tensor, Tensor]:
    """One query's sampling locations and weights, heads averaged so its weights sum to 1.

    Args:
        sampling_grid: (S, Q, heads, A, P, 2) grid coordinates.
        weights: (S, Q, heads, A, P) attention weights (each head's sum to 1 over S, A, P when visible).
        query: row-major plane index.
    Returns:
        uv_pix (S, heads*A*P, 2) and weight (S, heads*A*P).
    """
    S, _, heads = weights.shape[:3]
    # S, Q, heads, A, P, 2 -> S, heads, A, P, 2 -> S, heads*A*P, 2
    uv_pix = grid_to_pixels(sampling_grid[:, query].reshape(S, -1, 2), image_hw)
    return uv_pix, weights[:, query].reshape(S, -1) / heads


@dataclass(frozen=True)
class PlaneView:
    """How the query plane is drawn: which world axis runs across and up, and which way.

    Bird's-eye (pillar z): y across, increasing to the left (the robot's left is on the left when
    looking forward along +x), x up. Other planes: the non-z axis across, z up.
    """

    across: int
    up: int
    flip_across: bool

    @classmethod
    def of(cls, volume: FeatureVolume) -> PlaneView:
        a, b = volume.plane_axes
        if volume.pillar_axis == "z":
            return cls(across=b, up=a, flip_across=True)
        return cls(across=a, up=b, flip_across=AXES[a] == "y")

    def image(self, heat: np.ndarray, volume: FeatureVolume) -> np.ndarray:
        """(Na, Nb) plane map -> (rows up, cols across) for ``imshow(origin="lower")``."""
        return heat if self.up == volume.plane_axes[0] else heat.T

    def extent(self, volume: FeatureVolume) -> tuple[float, float, float, float]:
        (left, right), (bottom, top) = volume.bounds[self.across], volume.bounds[self.up]
        return left, right, bottom, top


@dataclass
class FrameData:
    """Everything one drawn frame shows (numpy, for the displayed images).

    Attributes:
        images: per camera name, (H, W, 3) uint8.
        anchor_uv: (S, M, 2) pixels of the drawn anchors; anchor_visible (S, M); anchor_height (M,) z in m.
        sample_uv: (S, N, 2) the chosen query's sampling points; sample_weight (S, N).
        query_uv: (S, A, 2) the chosen query's pillar anchors; query_visible (S, A).
        heat: (Na, Nb) channel-compressed plane (:func:`bev_heatmap`); heat_label: its colour bar label.
        share_all, share_query: (S,) attention share per camera, over all queries / the chosen one.
        objects: name -> world xyz (3,) when the source knows them; objects_uv (S, K, 2), objects_visible.
    """

    title: str
    images: dict[str, np.ndarray]
    anchor_uv: np.ndarray
    anchor_visible: np.ndarray
    anchor_height: np.ndarray
    sample_uv: np.ndarray
    sample_weight: np.ndarray
    query: tuple[int, int]
    query_uv: np.ndarray
    query_visible: np.ndarray
    heat: np.ndarray
    heat_label: str
    share_all: np.ndarray
    share_query: np.ndarray
    objects: dict[str, np.ndarray]
    objects_uv: np.ndarray
    objects_visible: np.ndarray


def frame_data(
    out: OFGOutput,
    volume: FeatureVolume,
    images: dict[str, np.ndarray],
    pix_T_cam: Tensor,
    cam_T_world: Tensor,
    objects: dict[str, np.ndarray],
    query: tuple[int, int] | None,
    max_anchors: int,
    title: str = "",
) -> FrameData:
    """Gather what :func:`draw_frame` shows from the OFG output of one fused step (batch size 1).

    ``pix_T_cam`` (S, 3, 3) is for the displayed ``images`` (S cameras, in order); ``query`` None picks
    the cell under the first object, else the plane centre.
    """
    image_hw = next(iter(images.values())).shape[:2]
    anchor_grid, anchor_visible = out.geometry.anchor_grid[0].cpu(), out.geometry.anchor_visible[0].cpu()
    grid, weights = out.sampling_grid[0].cpu(), out.attention_weights[0].cpu()
    xyz = torch.tensor(np.array(list(objects.values())).reshape(-1, 3), dtype=torch.float32)
    if query is None:
        first = query_index(volume, xyz[0].numpy()) if objects else None
        query = first or (volume.plane_shape[0] // 2, volume.plane_shape[1] // 2)
    q = query[0] * volume.plane_shape[1] + query[1]
    lattice = anchor_lattice(volume, max_anchors)  # Q, A
    channels = out.compressed.shape[-1]
    sample_uv, sample_weight = query_samples(grid, weights, q, image_hw)
    objects_uv, objects_visible = project_points(pix_T_cam, cam_T_world, xyz, image_hw)
    return FrameData(
        title=title,
        images=images,
        anchor_uv=grid_to_pixels(anchor_grid[:, lattice], image_hw).numpy(),
        anchor_visible=anchor_visible[:, lattice].numpy(),
        anchor_height=volume.anchors_world()[lattice][:, 2].numpy(),
        sample_uv=sample_uv.numpy(),
        sample_weight=sample_weight.numpy(),
        query=query,
        query_uv=grid_to_pixels(anchor_grid[:, q], image_hw).numpy(),
        query_visible=anchor_visible[:, q].numpy(),
        heat=bev_heatmap(out.compressed[0].float().cpu(), volume.plane_shape).numpy(),
        heat_label=f"compressed plane feature{'' if channels == 1 else f' (L2 of {channels} channels)'}",
        share_all=attention_share(weights).numpy(),
        share_query=attention_share(weights[:, q]).numpy(),
        objects=dict(objects),
        objects_uv=objects_uv.numpy(),
        objects_visible=objects_visible.numpy(),
    )


def draw_frame(frame: FrameData, volume: FeatureVolume, dpi: int = 100) -> Figure:
    """One figure: a panel per camera, the BEV heatmap and the attention share per camera."""
    cams = list(frame.images)
    ncols = max(len(cams), 2)
    width = PANEL_INCHES * ncols + 1.0
    fig = Figure(figsize=(width, PANEL_INCHES * (1 + BEV_SCALE) + 0.8), dpi=dpi)
    FigureCanvasAgg(fig)
    # Margins in inches, so that colour bar labels fit whatever the number of cameras.
    grid = fig.add_gridspec(
        2, ncols + 1, width_ratios=[1] * ncols + [0.06], height_ratios=[1, BEV_SCALE], left=0.3 / width,
        right=1 - 0.75 / width, top=0.91, bottom=0.07, hspace=0.22, wspace=0.22,
    )  # fmt: skip
    fig.suptitle(frame.title, fontsize=11)
    z_lo, z_hi = volume.bounds[2]
    w_max = max(float(frame.sample_weight.max()), 1e-12)
    weight_colors = ScalarMappable(Normalize(0.0, w_max), WEIGHT_CMAP)
    for s, cam in enumerate(cams):
        ax = fig.add_subplot(grid[0, s])
        ax.imshow(frame.images[cam])
        vis = frame.anchor_visible[s]
        anchors = ax.scatter(*frame.anchor_uv[s, vis].T, c=frame.anchor_height[vis], cmap=ANCHOR_CMAP,
                             vmin=z_lo, vmax=z_hi, s=ANCHOR_SIZE, alpha=0.8, linewidths=0)  # fmt: skip
        ax.plot(*frame.query_uv[s, frame.query_visible[s]].T, color="white", lw=1.0, path_effects=OUTLINE)
        sel = frame.sample_weight[s] > 0
        w = frame.sample_weight[s, sel]
        # Hollow rings, so that the object under the query stays visible.
        ax.scatter(*frame.sample_uv[s, sel].T, s=SAMPLE_MIN_SIZE + SAMPLE_MAX_SIZE * w / w_max,
                   facecolors="none", edgecolors=weight_colors.to_rgba(w), linewidths=1.2)  # fmt: skip
        for k in range(len(frame.objects)):
            if frame.objects_visible[s, k]:
                ax.plot(*frame.objects_uv[s, k], marker="+", color=OBJECT_COLOR, ms=8, mew=1.5)
        height, width = frame.images[cam].shape[:2]
        ax.set(xlim=(-0.5, width - 0.5), ylim=(height - 0.5, -0.5), xticks=[], yticks=[])
        ax.set_title(f"{cam}: {100 * frame.share_all[s]:.0f}% of attention", fontsize=9)
    bars = grid[0, ncols].subgridspec(2, 1, hspace=0.5)
    fig.colorbar(anchors, cax=fig.add_subplot(bars[0])).set_label("anchor height z (m)", fontsize=8)
    fig.colorbar(weight_colors, cax=fig.add_subplot(bars[1])).set_label("query sample weight", fontsize=8)
    split = ncols - 1  # the bar chart takes one column
    _draw_bev(fig.add_subplot(grid[1, :split]), frame, volume)
    _draw_share(fig.add_subplot(grid[1, split:ncols]), frame, cams)
    return fig


def _draw_bev(ax, frame: FrameData, volume: FeatureVolume) -> None:
    view = PlaneView.of(volume)
    heat = view.image(frame.heat, volume)
    limit = max(float(np.abs(heat).max()), 1e-12)
    signed = bool(heat.min() < 0)
    cmap, vmin = (BEV_SIGNED_CMAP, -limit) if signed else (BEV_CMAP, float(heat.min()))
    im = ax.imshow(heat, origin="lower", extent=view.extent(volume), interpolation="nearest", aspect="equal",
                   cmap=cmap, vmin=vmin, vmax=limit)  # fmt: skip
    ax.figure.colorbar(im, ax=ax, fraction=0.05, pad=0.03).set_label(frame.heat_label, fontsize=8)
    cell = [(hi - lo) / n for (lo, hi), n in zip(volume.bounds, volume.shape, strict=True)]
    lo = {k: volume.bounds[k][0] + i * cell[k] for k, i in zip(volume.plane_axes, frame.query, strict=True)}
    ax.add_patch(Rectangle((lo[view.across], lo[view.up]), cell[view.across], cell[view.up], fill=False,
                           edgecolor=QUERY_COLOR, lw=1.8, label=f"query {frame.query}"))  # fmt: skip
    span = max(hi - lo for lo, hi in volume.bounds)
    labelled: list[np.ndarray] = []
    for name, xyz in frame.objects.items():
        xy = np.array([xyz[view.across], xyz[view.up]])
        ax.plot(*xy, marker="+", color=OBJECT_COLOR, ms=10, mew=2)
        if all(np.linalg.norm(xy - other) > LABEL_SPACING * span for other in labelled):  # no pile-ups
            labelled.append(xy)
            ax.annotate(name, xy, xytext=(4, 3), textcoords="offset points", color=OBJECT_COLOR, fontsize=8,
                        path_effects=OUTLINE)  # fmt: skip
    if view.flip_across:
        ax.invert_xaxis()
    ax.set_xlabel(f"{AXES[view.across]} (m)" + (", left ←" if view.flip_across else ""), fontsize=9)
    ax.set_ylabel(f"{AXES[view.up]} (m)" + (", forward ↑" if AXES[view.up] == "x" else ""), fontsize=9)
    plane = "".join(AXES[k] for k in volume.plane_axes)
    kind = "bird's-eye plane" if volume.pillar_axis == "z" else f"{plane} plane"
    ax.set_title(f"{kind}, robot base frame" + (" (+ objects)" if frame.objects else ""), fontsize=9)
    ax.legend(loc="upper right", fontsize=7, framealpha=0.7)


def _draw_share(ax, frame: FrameData, cams: list[str]) -> None:
    x = np.arange(len(cams))
    ax.bar(x - 0.2, 100 * frame.share_all, width=0.4, label="all queries", color="tab:blue")
    ax.bar(x + 0.2, 100 * frame.share_query, width=0.4, label=f"query {frame.query}", color="tab:orange")
    ax.axhline(100 / len(cams), color="grey", lw=0.8, ls="--", label="uniform")
    ax.set_xticks(x, cams)
    ax.yaxis.tick_right()  # keeps clear of the BEV's colour bar on the left
    ax.yaxis.set_label_position("right")
    ax.set_ylabel("share of attention weight (%)", fontsize=9)
    ax.set_ylim(0, 100)
    ax.set_title("attention per camera (last layer)", fontsize=9)
    ax.legend(fontsize=8)


def figure_rgb(fig: Figure) -> np.ndarray:
    """(H, W, 3) uint8 rendering of a figure (its size in inches times its dpi)."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def write_mp4(path: Path, frames: Iterator[np.ndarray], fps: float) -> int:
    """Encode (H, W, 3) uint8 frames with PyAV (H.264, or MPEG-4 without libx264); returns the count.

    Written to a temporary name and renamed at the end, so an interrupted run leaves no broken file.
    """
    import av

    codec = next((c for c in VIDEO_CODECS if c in av.codecs_available), None)
    if codec is None:
        raise RuntimeError(f"PyAV has none of the video encoders {list(VIDEO_CODECS)}")
    partial = path.with_name(path.stem + ".partial.mp4")
    count = 0
    try:
        with av.open(str(partial), mode="w") as container:
            stream = None
            for rgb in frames:
                # yuv420p needs even sides: repeat the last row / column where odd.
                rgb = np.pad(rgb, ((0, rgb.shape[0] % 2), (0, rgb.shape[1] % 2), (0, 0)), mode="edge")
                if stream is None:
                    stream = container.add_stream(codec, rate=Fraction(fps).limit_denominator(1000))
                    stream.height, stream.width = rgb.shape[:2]
                    stream.pix_fmt = "yuv420p"
                container.mux(stream.encode(av.VideoFrame.from_ndarray(rgb, format="rgb24")))
                count += 1
            if stream is not None:
                container.mux(stream.encode())
        partial.replace(path)
    finally:
        partial.unlink(missing_ok=True)
    return count
