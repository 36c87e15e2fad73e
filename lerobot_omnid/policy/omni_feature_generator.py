"""Omni-Feature Generator (OFG): multi-camera image features -> a 3D feature volume by deformable attention.

Shape legend: B batch, S cameras, C channels, H W feature map, Q plane queries, A anchors per pillar,
P points per anchor, N = A * P samples per query per camera and head, D = d_model.

Every plane query owns a pillar of A anchors in the robot base frame. Each anchor is projected into
every camera with that sample's own K and T_cam_world; a network shared by all cameras (fed with the
query and the camera's geometry relative to the pillar, never with a camera identity) predicts P
sampling offsets and an attention weight per anchor, camera and head. Weights are normalised over the
visible (camera, anchor, point) triples, so any number and subset of cameras works.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from lerobot_omnid.geometry import (
    camera_centers_world,
    clamp_to_feature_cells,
    grid_to_pixels,
    pixels_to_feature_grid,
    project_to_grid,
)
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.deformable_sampling import multi_camera_deformable_sampling
from lerobot_omnid.policy.plane_readout import (
    BEVConvReadout,
    KeypointFeatureReadout,
    LatentQueryReadout,
    plane_keypoints,
)

CAMERA_GEOMETRY_DIM = 6  # unit ray camera->pillar centre (3), its grid coordinates (2), visible anchors (1)


@dataclass
class CameraGeometry:
    """Where the volume's anchors fall in each camera of each sample.

    Attributes:
        anchor_grid: (B, S, Q, A, 2) anchors in ``grid_sample`` coordinates of each camera's image.
        anchor_visible: (B, S, Q, A) bool: anchor in front of the camera and inside its image.
        descriptor: (B, S, Q, CAMERA_GEOMETRY_DIM) camera-relative geometry of each pillar.
        image_hw: (height, width) of the images the grid coordinates refer to (the backbone's input).
    """

    anchor_grid: Tensor
    anchor_visible: Tensor
    descriptor: Tensor
    image_hw: tuple[int, int]


def camera_geometry(
    anchors_world: Tensor, pix_T_cam: Tensor, cam_T_world: Tensor, image_hw: tuple[int, int]
) -> CameraGeometry:
    """Project every anchor into every camera of every sample.

    Args:
        anchors_world: (Q, A, 3) anchor positions in the world frame.
        pix_T_cam: (B, S, 3, 3) intrinsics for images of ``image_hw``.
        cam_T_world: (B, S, 4, 4) extrinsics.
        image_hw: (height, width) of the images the intrinsics refer to.
    """
    Q, A, _ = anchors_world.shape
    B, S = pix_T_cam.shape[:2]
    grid, visible = project_to_grid(pix_T_cam, cam_T_world, anchors_world.reshape(Q * A, 3), image_hw)
    anchor_grid = grid.reshape(B, S, Q, A, 2)
    anchor_visible = visible.reshape(B, S, Q, A)

    pillar_world = anchors_world.mean(dim=1)  # Q, 3
    ray = pillar_world - camera_centers_world(cam_T_world)[:, :, None, :]  # B, S, Q, 3
    ray = ray / ray.norm(dim=-1, keepdim=True).clamp(min=1e-6)
    centre_grid, _ = project_to_grid(pix_T_cam, cam_T_world, pillar_world, image_hw)  # B, S, Q, 2
    descriptor = torch.cat(
        [ray, centre_grid.clamp(-2.0, 2.0), anchor_visible.float().mean(dim=-1, keepdim=True)], dim=-1
    )
    return CameraGeometry(anchor_grid, anchor_visible, descriptor, tuple(image_hw))


class CameraCrossAttention(nn.Module):
    """Deformable attention from the plane queries to the feature maps of all cameras.

    ``feature_stride`` and ``feature_offset`` say where the feature cells are in the image (cell ``j``
    centred on pixel ``feature_stride * j + feature_offset``): samples are taken there, for any image size.
    """

    def __init__(
        self, config: OmniDConfig, num_anchors: int, feature_stride: int, feature_offset: float
    ) -> None:
        super().__init__()
        self.feature_stride = feature_stride
        self.feature_offset = feature_offset
        self.num_heads = config.num_heads
        self.num_anchors = num_anchors
        self.num_points = config.num_points
        self.query_chunk_size = config.query_chunk_size
        self.checkpoint_sampling = config.checkpoint_sampling
        d = config.d_model
        n_samples = self.num_heads * num_anchors * self.num_points
        self.camera_embed = nn.Sequential(nn.Linear(CAMERA_GEOMETRY_DIM, d), nn.ReLU(), nn.Linear(d, d))
        self.sampling_offsets = nn.Linear(d, n_samples * 2)
        self.attention_logits = nn.Linear(d, n_samples)
        self.value_proj = nn.Linear(d, d)
        self.output_proj = nn.Linear(d, d)
        self._reset_parameters()

    def _reset_parameters(self) -> None:
        # Start with the points of each anchor on a ring of radius 1..P feature cells around its projection.
        nn.init.zeros_(self.sampling_offsets.weight)
        P = self.num_points
        angles = torch.arange(P) * (2 * torch.pi / P)
        ring = torch.stack([angles.cos(), angles.sin()], dim=-1) * (torch.arange(P)[:, None] + 1)
        ring = ring if P > 1 else torch.zeros(1, 2)
        bias = ring.view(1, 1, P, 2).expand(self.num_heads, self.num_anchors, P, 2)
        with torch.no_grad():
            self.sampling_offsets.bias.copy_(bias.reshape(-1))
        nn.init.zeros_(self.attention_logits.weight)
        nn.init.zeros_(self.attention_logits.bias)

    def forward(
        self, queries: Tensor, features: Tensor, geometry: CameraGeometry
    ) -> tuple[Tensor, Tensor, Tensor]:
        """
        Args:
            queries: (B, Q, D).
            features: (B, S, D, H, W) per-camera feature maps.
            geometry: projections of the anchors, see :func:`camera_geometry`.
        Returns:
            out: (B, Q, D) fused features.
            sampling_grid: (B, S, Q, heads, A, P, 2) where each sample was taken, in the image's grid
                coordinates (``geometry.image_hw``).
            weights: (B, S, Q, heads, A, P) its attention weight (zero where not visible).
        """
        B, S, D, H, W = features.shape
        Q, heads, A, P = queries.shape[1], self.num_heads, self.num_anchors, self.num_points
        image_h, image_w = geometry.image_hw

        camera_queries = queries[:, None] + self.camera_embed(geometry.descriptor)  # B, S, Q, D
        # Offsets are predicted in feature cells (``feature_stride`` pixels each), drawn in the image's grid
        # coordinates: B, S, Q, heads*A*P*2 -> B, S, Q, heads, A, P, 2
        offsets = self.sampling_offsets(camera_queries).view(B, S, Q, heads, A, P, 2)
        offsets = offsets * offsets.new_tensor([2.0 / image_w, 2.0 / image_h]) * self.feature_stride
        # B, S, Q, A, 2 -> B, S, Q, 1, A, 1, 2 (+ offsets) -> B, S, Q, heads, A, P, 2
        sampling_grid = geometry.anchor_grid[:, :, :, None, :, None, :] + offsets
        # Image grid -> pixels (inside the image: onto the cells that cover them) -> the feature map's own
        # grid, where each cell really is.
        uv_pix = clamp_to_feature_cells(
            grid_to_pixels(sampling_grid, geometry.image_hw),
            geometry.image_hw,
            (H, W),
            self.feature_stride,
            self.feature_offset,
        )
        feature_grid = pixels_to_feature_grid(uv_pix, (H, W), self.feature_stride, self.feature_offset)

        logits = self.attention_logits(camera_queries).view(B, S, Q, heads, A, P)
        mask = geometry.anchor_visible[:, :, :, None, :, None].expand(B, S, Q, heads, A, P)
        logits = logits.masked_fill(~mask, torch.finfo(logits.dtype).min)
        # Normalise over cameras x anchors x points: B, S, Q, heads, A, P -> B, Q, heads, S*A*P
        weights = logits.permute(0, 2, 3, 1, 4, 5).reshape(B, Q, heads, S * A * P).softmax(dim=-1)
        # Back to B, S, Q, heads, A, P; a query seen by no camera gets all-zero weights.
        weights = weights.view(B, Q, heads, S, A, P).permute(0, 3, 1, 2, 4, 5) * mask

        # B, S, D, H, W -> B, S, H, W, D -> (value proj) -> B, S, heads, D/heads, H, W
        values = self.value_proj(features.permute(0, 1, 3, 4, 2))
        values = values.view(B, S, H, W, heads, D // heads).permute(0, 1, 4, 5, 2, 3)
        fused = multi_camera_deformable_sampling(
            values,
            feature_grid.reshape(B, S, Q, heads, A * P, 2),
            weights.reshape(B, S, Q, heads, A * P),
            query_chunk_size=self.query_chunk_size,
            use_checkpoint=self.checkpoint_sampling and self.training,
        )
        return self.output_proj(fused), sampling_grid, weights


class QuerySelfAttention(nn.Module):
    """Multi-head self-attention among the plane queries (scaled_dot_product_attention kernels)."""

    def __init__(self, d_model: int, num_heads: int, dropout: float) -> None:
        super().__init__()
        self.num_heads = num_heads
        self.dropout = dropout
        self.qkv = nn.Linear(d_model, 3 * d_model)
        self.out = nn.Linear(d_model, d_model)

    def forward(self, x: Tensor) -> Tensor:
        """(B, Q, D) -> (B, Q, D)."""
        B, Q, D = x.shape
        # B, Q, 3*D -> 3, B, heads, Q, D/heads
        q, k, v = self.qkv(x).view(B, Q, 3, self.num_heads, D // self.num_heads).permute(2, 0, 3, 1, 4)
        attn = F.scaled_dot_product_attention(q, k, v, dropout_p=self.dropout if self.training else 0.0)
        return self.out(attn.transpose(1, 2).reshape(B, Q, D))


class OFGLayer(nn.Module):
    """(optional) query self-attention, camera cross-attention, feed-forward; post-norm residuals."""

    def __init__(
        self, config: OmniDConfig, num_anchors: int, feature_stride: int, feature_offset: float
    ) -> None:
        super().__init__()
        d = config.d_model
        self.self_attn = (
            QuerySelfAttention(d, config.num_heads, config.dropout) if config.use_self_attention else None
        )
        self.norm_self = nn.LayerNorm(d) if config.use_self_attention else None
        self.cross_attn = CameraCrossAttention(config, num_anchors, feature_stride, feature_offset)
        self.norm_cross = nn.LayerNorm(d)
        self.ffn = nn.Sequential(
            nn.Linear(d, config.ffn_dim), nn.ReLU(), nn.Dropout(config.dropout), nn.Linear(config.ffn_dim, d)
        )
        self.norm_ffn = nn.LayerNorm(d)
        self.dropout = nn.Dropout(config.dropout)

    def forward(
        self, queries: Tensor, query_pos: Tensor, features: Tensor, geometry: CameraGeometry
    ) -> tuple[Tensor, Tensor, Tensor]:
        """queries (B, Q, D), query_pos (Q, D), features (B, S, D, H, W) -> (B, Q, D), grid, weights."""
        if self.self_attn is not None:
            queries = self.norm_self(queries + self.dropout(self.self_attn(queries + query_pos)))
        fused, grid, weights = self.cross_attn(queries + query_pos, features, geometry)
        queries = self.norm_cross(queries + self.dropout(fused))
        queries = self.norm_ffn(queries + self.dropout(self.ffn(queries)))
        return queries, grid, weights


@dataclass
class OFGOutput:
    """The fused volume and, for inspection, the last layer's sampling.

    Attributes:
        plane: (B, Q, D) features of the plane queries (row-major over ``FeatureVolume.plane_shape``).
        compressed: (B, Q, compressed_channels) channel-compressed plane.
        condition: (B, out_dim) the image condition read from ``compressed`` (``config.plane_readout``).
        sampling_grid: (B, S, Q, heads, A, P, 2) last layer's sampling locations (grid coordinates).
        attention_weights: (B, S, Q, heads, A, P) last layer's attention weights.
        geometry: anchor projections.
    """

    plane: Tensor
    compressed: Tensor
    condition: Tensor
    sampling_grid: Tensor
    attention_weights: Tensor
    geometry: CameraGeometry


class OmniFeatureGenerator(nn.Module):
    """Multi-camera feature maps + calibration -> flattened, channel-compressed plane feature."""

    def __init__(
        self, config: OmniDConfig, in_channels: int, feature_stride: int, feature_offset: float
    ) -> None:
        super().__init__()
        volume = config.feature_volume
        self.register_buffer("anchors_world", volume.anchors_world(), persistent=False)  # Q, A, 3
        self.register_buffer("plane_coords", volume.plane_coords_normalized(), persistent=False)  # Q, 3
        # Q, 2: where each query lies on the plane, in [-1, 1], for the keypoint readout
        self.register_buffer("plane_xy", self.plane_coords[:, list(volume.plane_axes)], persistent=False)
        self.plane_readout = config.plane_readout
        d = config.d_model
        self.input_proj = nn.Sequential(nn.Conv2d(in_channels, d, kernel_size=1), nn.GroupNorm(1, d))
        self.query_embed = nn.Parameter(torch.randn(volume.num_queries, d) * 0.02)
        self.query_pos = nn.Sequential(nn.Linear(3, d), nn.ReLU(), nn.Linear(d, d))
        self.layers = nn.ModuleList(
            OFGLayer(config, volume.num_anchors, feature_stride, feature_offset)
            for _ in range(config.num_layers)
        )
        self.compress = nn.Linear(d, config.compressed_channels)
        c = config.compressed_channels
        # flatten and keypoints have no parameters of their own (and checkpoints saved with them none).
        self.readout: nn.Module | None = None
        if config.plane_readout == "flatten":
            if config.zero_init_compression:  # see the config: the condition grows from zero as it trains
                nn.init.zeros_(self.compress.weight)
                nn.init.zeros_(self.compress.bias)
            self.out_dim = volume.num_queries * c
        elif config.plane_readout == "keypoints":
            self.out_dim = 2 * c
        else:
            if config.plane_readout == "keypoint_features":
                self.readout = KeypointFeatureReadout(d, c, config.readout_dim)
            elif config.plane_readout == "latent_queries":
                self.readout = LatentQueryReadout(
                    d, config.num_heads, config.readout_latents, config.readout_dim
                )
            else:
                self.readout = BEVConvReadout(c, volume.plane_shape, config.readout_dim)
            self.out_dim = self.readout.out_dim

    def forward(
        self,
        feature_maps: Tensor,
        pix_T_cam: Tensor,
        cam_T_world: Tensor,
        image_hw: tuple[int, int],
        camera_mask: Tensor | None = None,
    ) -> OFGOutput:
        """
        Args:
            feature_maps: (B, S, C, H, W) backbone features of each camera.
            pix_T_cam: (B, S, 3, 3) intrinsics for the backbone's input images of ``image_hw``.
            cam_T_world: (B, S, 4, 4) extrinsics.
            image_hw: (height, width) of the backbone's input images.
            camera_mask: (B, S) bool, False for a camera to leave out (as if it saw none of the volume).
        """
        B, S = feature_maps.shape[:2]
        # Projections in full precision: under autocast the matmuls would run in fp16 / bf16, moving
        # projections by pixels and flipping the visibility of anchors near the image edges.
        with torch.autocast(feature_maps.device.type, enabled=False):
            geometry = camera_geometry(
                self.anchors_world.float(), pix_T_cam.float(), cam_T_world.float(), image_hw
            )
        if camera_mask is not None:
            visible = geometry.anchor_visible & camera_mask[:, :, None, None]
            geometry = dataclasses.replace(geometry, anchor_visible=visible)
        # B, S, C, H, W -> B*S, C, H, W -> B*S, D, H, W -> B, S, D, H, W
        features = self.input_proj(feature_maps.flatten(0, 1)).unflatten(0, (B, S))
        query_pos = self.query_pos(self.plane_coords)  # Q, D
        queries = self.query_embed.expand(B, -1, -1)
        for layer in self.layers:
            queries, grid, weights = layer(queries, query_pos, features, geometry)
        compressed = self.compress(queries)  # B, Q, c
        if self.plane_readout == "flatten":
            condition = compressed.flatten(1)  # B, Q*c
        elif self.plane_readout == "keypoints":
            condition = plane_keypoints(compressed, self.plane_xy).flatten(1)  # B, c, 2 -> B, 2c
        else:
            condition = self.readout(queries, compressed, self.plane_xy)
        return OFGOutput(queries, compressed, condition, grid, weights, geometry)
