"""Configuration of the OmniD policy (multi-view BEV features by deformable attention + diffusion head)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

from lerobot.configs import FeatureType, NormalizationMode, PreTrainedConfig
from lerobot.optim import AdamWConfig, DiffuserSchedulerConfig
from lerobot.utils.constants import OBS_ENV_STATE
from lerobot.utils.feature_utils import dataset_to_policy_features

from lerobot_omnid.calibration.frame_columns import extrinsics_key, intrinsics_key, is_calibration_key
from lerobot_omnid.calibration.rig_file import load_calibration_file
from lerobot_omnid.calibration.schema import (
    CALIBRATION_INFO_KEY,
    CalibrationError,
    CameraCalibration,
    calibration_from_feature_info,
)
from lerobot_omnid.camera_visibility import CAMERA_VISIBLE_KEY
from lerobot_omnid.cli import check_choice, check_positive_int
from lerobot_omnid.geometry import AXES, PAPER_VOLUME_BOUNDS, FeatureVolume
from lerobot_omnid.keys import camera_name, image_key
from lerobot_omnid.policy.plane_readout import PLANE_READOUTS

BACKBONES = ("resnet18", "resnet34", "resnet50", "resnet101")
FREEZABLE = ("backbone", "ofg", "head")
"""Parts of the model that ``frozen_modules`` can keep from training."""
NOISE_SCHEDULERS = ("DDPM", "DDIM")
PREDICTION_TYPES = ("epsilon", "sample")
OFG_ONLY_OPTIONS = {
    "random_crop_min_scale": 1.0,
    "camera_rotation_deg": 0.0,
    "calibration_noise_rotation_deg": 0.0,
    "calibration_noise_translation_mm": 0.0,
    "calibration_noise_focal_pct": 0.0,
    "calibration_noise_principal_px": 0.0,
    "camera_dropout": 0.0,
    "single_camera_rate": 0.0,
    "position_shift_m": 0.0,
}
"""Training augmentations that act in the OFG's path, each with the value that turns it off."""

logger = logging.getLogger(__name__)


@PreTrainedConfig.register_subclass("omnid")
@dataclass
class OmniDConfig(PreTrainedConfig):
    """Configuration of OmniDPolicy. Defaults follow the paper (section 3).

    Fields a user will most likely change: ``volume_bounds`` (the workspace of the robot, in its base
    frame), ``resize_shape`` and the model sizes (``d_model``, ``num_layers``, ``volume_shape``,
    ``down_dims``) to fit the hardware, ``num_inference_steps`` with ``noise_scheduler_type="DDIM"`` for
    fast evaluation. ``camera_calibration`` is filled from the dataset when the policy is made; every
    ``observation.images.*`` input needs an entry. An ``observation.environment_state`` input (FeatureType
    ENV; e.g. the task one-hot of ``omnid-record --task-onehot``, so that one policy trained on several tasks
    is told which one it is asked for) is appended to the state in the diffusion head's condition at every
    observation step, as LeRobot's DiffusionPolicy does; without one the model is unchanged.

    Args:
        n_obs_steps: Number of observation steps (current and previous) the policy conditions on.
        horizon: Number of action steps predicted by the diffusion head.
        n_action_steps: Number of predicted actions executed before predicting again.
        drop_n_last_frames: Frames at the end of each episode not used as training start points.
        normalization_mapping: Normalisation per feature type. Images are not normalised with dataset
            statistics (IDENTITY): the backbone normalises with fixed ImageNet statistics, so a camera that
            was not in the training set (fine-tuning, evaluation on a new view) is handled like the others.
            Nor is the env state (ENV, IDENTITY): a task one-hot is already in [0, 1], and MIN_MAX would
            map its columns that are constant in a single-task dataset to -1 (the set one and the unset
            ones alike) and a value outside their one-point range to about 2 / eps.
        camera_calibration: Per image feature key, the calibration dict of
            :class:`lerobot_omnid.calibration.schema.CameraCalibration` (K, T_cam_world, image_size).
            Copied from the dataset's feature info by ``set_dataset_feature_metadata``; saved in
            ``config.json``.
        frame_calibration: Image feature keys whose calibration is read from every frame instead, from
            the columns ``observation.extrinsics.<cam>`` / ``observation.intrinsics.<cam>``
            (:mod:`lerobot_omnid.calibration.frame_columns`), per sample and observation step: a wrist
            camera, or data merged from several rigs. Set from the dataset when both columns of a used
            camera exist (they then win over a static calibration in the feature info); the columns are
            kept out of ``input_features``, so they are neither normalised nor part of the state.
        camera_visible_names: The recorded cameras' names of the dataset's column
            ``observation.camera_visible`` (:mod:`lerobot_omnid.camera_visibility`, written by
            ``omnid-record --hidden-cameras``), in its order: the feature's ``names``, set from the dataset
            by ``set_dataset_feature_metadata`` and saved in ``config.json``; None when the dataset has no
            such column. Whenever a batch has the column, in training and at inference, each sample fuses
            only those of the policy's cameras (matched by name: the policy may use a subset, in another
            order) that every one of its observation steps marks visible, AND-ed with ``camera_dropout`` in
            training. The column is kept out of ``input_features``, so it is neither normalised nor part of
            the state. An env never sends it: evaluation is unchanged. Needs the OFG (``use_ofg``).
        cameras: Which of the dataset's cameras the policy uses, by name ("cam_b") or feature key
            ("observation.images.cam_b"); None uses every image feature of the dataset.
        calibration_path: A calibration file (``lerobot_omnid.calibration.rig_file``) whose cameras override
            ``camera_calibration`` and the dataset's, e.g. to evaluate on a rig whose cameras moved. Read
            once when the config is made and merged into ``camera_calibration``; then set to None, so a
            saved ``config.json`` carries the calibration itself and never depends on the file. A file none
            of whose cameras the policy uses, or with an entry for a camera in ``frame_calibration``, is
            refused, since it would be ignored.
        vision_backbone: torchvision ResNet shared by all cameras ("resnet18"; "resnet101" for the
            paper's ablation).
        pretrained_backbone_weights: Pretrained backbone weights, as LeRobot's diffusion policy takes them:
            a torchvision weights name of ``vision_backbone`` ("ResNet18_Weights.IMAGENET1K_V1"; torchvision
            downloads it, so only where the machine is online), or a local state-dict file (for offline
            machines: ``torch.save(torchvision.models.resnet18(weights=...).state_dict(), path)`` where
            online). None (the default) initialises randomly. Needs ``use_group_norm=False``.
        use_group_norm: Replace BatchNorm by GroupNorm (16 channels per group) in the backbone; BatchNorm
            statistics are unreliable with small batches of correlated frames.
        backbone_layer: Last ResNet stage used: 4 gives stride-32 features (as the authors' code), 3
            stride-16, 2 stride-8 and 1 stride-4 features (finer maps for small images).
        checkpoint_backbone: Recompute backbone activations in the backward pass (stage by stage) instead
            of storing them: much less memory at 480x480, about a third more backbone compute.
        resize_shape: (height, width) images are resized to before the backbone, intrinsics rescaled
            accordingly; None keeps the input size. With it, cameras may deliver different image sizes
            (each with its own calibration); without it, all cameras need one size.
        images_stretched: The images of a camera may have another aspect ratio than its calibration
            because they are the calibrated images stretched (K is then rescaled anisotropically).
            False (default): such images are refused, since a camera in another sensor mode (16:9 vs
            4:3) crops rather than stretches, and a rescaled K would be wrong.
        random_crop_min_scale: Geometric augmentation that keeps the calibration: in training, each
            sample's image of each camera (the same for all observation steps) is cut to a random crop
            of ``random_crop_min_scale``..1 of each side at a random position and resized back, and that
            sample's K is moved with it. 1.0 (default) disables it. Use this instead of LeRobot's
            dataset transforms ``RandomAffine`` / crops, which move the images but not K (LeRobot's
            photometric transforms, e.g. ColorJitter, are fine).
        camera_rotation_deg: Geometric augmentation that moves the camera and keeps the calibration true (0:
            off): in training, per sample and camera (the same for all observation steps) the camera is
            turned about its optical centre by a random angle up to this many degrees about a random axis;
            its images are warped to what it would then see (a pure rotation needs no depth: exact inside
            the old view, black outside it) and its extrinsics turned with it, so the OFG sees views and
            poses the rig never had. A moved camera also translates, which no image warp can make.
        calibration_noise_rotation_deg, calibration_noise_translation_mm: Training-time extrinsics noise
            (0: off): per sample and camera (the same for all observation steps) the camera is believed
            turned about its optical centre by a rotation vector with this standard deviation per axis
            (degrees) and moved by a translation with this standard deviation per axis (millimetres, camera
            frame), before the OFG projects the anchors. The scene and images are unchanged: the policy
            learns to tolerate calibration error.
        calibration_noise_focal_pct, calibration_noise_principal_px: Training-time intrinsics noise (0:
            off): focal lengths scaled by 1 + N(0, pct / 100), principal point moved by N(0, px) pixels of
            the backbone's input, per sample and camera.
        camera_dropout: Training-time probability of dropping each camera of a sample (its samples are
            masked out of the attention; at least one camera is always kept), so the fusion learns to work
            with whatever cameras are there. 0: off.
        single_camera_rate: Training-time share of samples that keep exactly one camera, drawn uniformly
            (after ``camera_dropout``): the OFG must then lift the scene from a single view, as it must for
            a new camera seen alone. 0: off; 1: every sample one camera.
        position_shift_m: Training-time translation of the whole scene (0: off): per sample a planar shift
            ``d``, uniform in ``[-position_shift_m, position_shift_m]`` metres along world x and y, moves the
            cameras' extrinsics, the state's and the action's TCP position together (robot, objects and
            cameras translated: the images stay true), so the head learns that an object seen ``d``
            farther needs a TCP target ``d`` farther. For absolute world-frame TCP actions (the omnid
            envs'); the state's joint angles do not move with it. The head must be able to command the
            shifted targets: with ``clip_sample`` the policy refuses a ``clip_sample_range`` that clips them
            (checked against the dataset's statistics at the first training step).
        state_position_dims, action_position_dims: Indices of the TCP's world x and y in
            ``observation.state`` and ``action``, for ``position_shift_m`` (the omnid envs': 0 and 1).
        fuse_last_step_only: Only the last observation step's images go through the backbone and the OFG
            (as in the authors' code); the state still conditions with all ``n_obs_steps``. Encoding
            costs 1 / n_obs_steps as much; what the head loses is the image history.
        use_ofg: False gives the paper's "w/o OFG" ablation: per-camera spatial-softmax features
            concatenated in camera order instead of the 3D feature (then the cameras are fixed). The
            augmentations of the OFG's path (``OFG_ONLY_OPTIONS``: crop, camera rotation, calibration noise,
            camera dropout, single camera, position shift) would do nothing there and must then be off.
        volume_bounds: ((x_min, x_max), (y_min, y_max), (z_min, z_max)) of the feature volume in the robot
            base frame, metres.
        volume_shape: Cells along (x, y, z).
        pillar_axis: Axis folded into pillars: one query per cell of the plane spanned by the two other
            axes, with one reference anchor per cell along the pillar. Default "z": a true bird's-eye
            plane over the table. (The authors' code used "y": an x-z plane.)
        d_model: Width of queries and sampled values.
        num_heads: Attention heads (each samples its own locations).
        num_layers: Layers of (query self-attention, camera cross-attention, feed-forward).
        num_points: Sampling points per anchor, per camera and head.
        ffn_dim: Hidden width of each layer's feed-forward network.
        dropout: Dropout in the OFG layers.
        use_self_attention: Whether each layer starts with self-attention among the plane queries.
        compressed_channels: Channels kept per query after the final 1x1 compression.
        plane_readout: How the compressed plane becomes the diffusion head's image condition.
            "flatten" (the paper's): all ``num_queries * compressed_channels`` values per observation
            step. "keypoints": a softmax over the plane per compressed channel and its expected plane
            coordinates, i.e. ``compressed_channels`` keypoints in the volume's normalised base-frame
            coordinates (``2 * compressed_channels`` values); it exists because in short CPU runs the
            flattened plane was ignored by the head (docs/results.md has the measurements).
            "keypoint_features", "latent_queries", "bev_conv": richer readouts
            (:mod:`lerobot_omnid.policy.plane_readout`): keypoints with the feature under each and a
            presence logit; ``readout_latents`` learned queries attending over the plane; a small strided
            CNN over the compressed plane with coordinate channels.
        readout_dim: Values per keypoint feature / per latent query, and bev_conv's condition / 8.
        readout_latents: Learned queries of the "latent_queries" readout.
        zero_init_compression: Start the compression at zero ("flatten" readout only; keypoints are
            bounded and start at the plane's centre), so that the plane enters the condition only
            as it becomes useful: an untrained encoder's plane varies at random from image to image and
            would drown the state for the diffusion head (docs/results.md has the measurements).
        query_chunk_size: Queries sampled at a time; bounds the memory of the sampling step.
        checkpoint_sampling: Recompute sampled features in the backward pass instead of storing them
            (much less memory at the paper's grid, about 30% more OFG compute).
        spatial_softmax_num_keypoints: Keypoints per camera in the "w/o OFG" ablation.
        down_dims, kernel_size, n_groups, diffusion_step_embed_dim, use_film_scale_modulation,
            gradient_checkpointing: LeRobot's `DiffusionConditionalUnet1d` settings.
        noise_scheduler_type: "DDPM" (training schedule of the paper) or "DDIM" (fewer inference steps).
        num_train_timesteps, beta_schedule, beta_start, beta_end, prediction_type, clip_sample,
            clip_sample_range: diffusers scheduler settings; the loss is on epsilon by default.
        num_inference_steps: Denoising steps at inference (None: ``num_train_timesteps``).
        do_mask_loss_for_padding: Mask the loss on copy-padded actions at episode ends.
        optimizer_*: AdamW settings (paper: AdamW, lr 1e-4).
        scheduler_name, scheduler_warmup_steps: cosine schedule with 500 warm-up steps (paper).
        frozen_modules: Parts not trained, of ``FREEZABLE``: "backbone" (the ResNet), "ofg" (the
            Omni-Feature Generator, or the per-camera keypoints without it) and "head" (the diffusion
            UNet). For fine-tuning: on a new camera, a head frozen keeps what was learnt from the plane to the
            actions, and only the lifting adapts. Default: none.
    """

    # Inputs / outputs.
    n_obs_steps: int = 2
    horizon: int = 16
    n_action_steps: int = 8
    drop_n_last_frames: int = 7  # horizon - n_action_steps - n_obs_steps + 1
    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {
            "VISUAL": NormalizationMode.IDENTITY,
            "ENV": NormalizationMode.IDENTITY,
            "STATE": NormalizationMode.MIN_MAX,
            "ACTION": NormalizationMode.MIN_MAX,
        }
    )
    camera_calibration: dict[str, dict] = field(default_factory=dict)
    frame_calibration: list[str] = field(default_factory=list)
    camera_visible_names: list[str] | None = None
    cameras: list[str] | None = None
    calibration_path: str | None = None

    # Image backbone.
    vision_backbone: str = "resnet18"
    pretrained_backbone_weights: str | None = None
    use_group_norm: bool = True
    backbone_layer: int = 4
    checkpoint_backbone: bool = False
    resize_shape: tuple[int, int] | None = None
    images_stretched: bool = False
    random_crop_min_scale: float = 1.0
    calibration_noise_rotation_deg: float = 0.0
    calibration_noise_translation_mm: float = 0.0
    calibration_noise_focal_pct: float = 0.0
    calibration_noise_principal_px: float = 0.0
    camera_dropout: float = 0.0
    single_camera_rate: float = 0.0
    position_shift_m: float = 0.0
    camera_rotation_deg: float = 0.0
    state_position_dims: tuple[int, int] = (0, 1)
    action_position_dims: tuple[int, int] = (0, 1)
    fuse_last_step_only: bool = False

    # Omni-Feature Generator.
    use_ofg: bool = True
    volume_bounds: tuple[tuple[float, float], ...] = PAPER_VOLUME_BOUNDS
    volume_shape: tuple[int, int, int] = (64, 16, 64)
    pillar_axis: str = "z"
    d_model: int = 128
    num_heads: int = 4
    num_layers: int = 6
    num_points: int = 1
    ffn_dim: int = 256
    dropout: float = 0.0
    use_self_attention: bool = True
    compressed_channels: int = 1
    plane_readout: str = "flatten"
    readout_dim: int = 8
    readout_latents: int = 4
    zero_init_compression: bool = True
    query_chunk_size: int = 512
    checkpoint_sampling: bool = True
    spatial_softmax_num_keypoints: int = 32

    # Diffusion head (LeRobot's conditional 1D UNet).
    down_dims: tuple[int, ...] = (512, 1024, 2048)
    kernel_size: int = 5
    n_groups: int = 8
    diffusion_step_embed_dim: int = 128
    use_film_scale_modulation: bool = True
    gradient_checkpointing: bool = False
    noise_scheduler_type: str = "DDPM"
    num_train_timesteps: int = 100
    beta_schedule: str = "squaredcos_cap_v2"
    beta_start: float = 0.0001
    beta_end: float = 0.02
    prediction_type: str = "epsilon"
    clip_sample: bool = True
    clip_sample_range: float = 1.0
    num_inference_steps: int | None = None
    do_mask_loss_for_padding: bool = False

    # Training presets.
    optimizer_lr: float = 1e-4
    optimizer_betas: tuple[float, float] = (0.95, 0.999)
    optimizer_eps: float = 1e-8
    optimizer_weight_decay: float = 1e-6
    scheduler_name: str = "cosine"
    scheduler_warmup_steps: int = 500
    frozen_modules: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        """Validate the fields (errors name the field, what was expected and what was given) and bring them
        into canonical form; read ``calibration_path``.

        The error is also logged before it is raised: ``lerobot-train --policy.type=omnid`` parses its
        options with draccus, which replaces a ``ValueError`` or ``TypeError`` raised while the config is
        built by "Couldn't instantiate class OmniDConfig" and drops its message, so without the log the
        command line user would never read what is wrong.
        """
        try:
            super().__post_init__()
            self._check_and_normalise()
        except (TypeError, ValueError) as error:
            logger.error("OmniDConfig: %s", error)
            raise

    def _check_and_normalise(self) -> None:
        """The checks and conversions of ``__post_init__``."""
        check_choice("vision_backbone", self.vision_backbone, BACKBONES)
        check_choice("noise_scheduler_type", self.noise_scheduler_type, NOISE_SCHEDULERS)
        check_choice("prediction_type", self.prediction_type, PREDICTION_TYPES)
        check_choice("pillar_axis", self.pillar_axis, AXES)
        check_choice("plane_readout", self.plane_readout, PLANE_READOUTS)
        check_choice("backbone_layer", self.backbone_layer, (1, 2, 3, 4))
        for name in (
            "d_model",
            "num_heads",
            "num_layers",
            "num_points",
            "ffn_dim",
            "compressed_channels",
            "readout_dim",
            "readout_latents",
            "query_chunk_size",
            "n_obs_steps",
            "horizon",
            "n_action_steps",
        ):
            check_positive_int(name, getattr(self, name))
        if self.d_model % self.num_heads:
            raise ValueError(
                f"`d_model` ({self.d_model}) must be divisible by `num_heads` ({self.num_heads})"
            )
        if self.n_action_steps > self.horizon - self.n_obs_steps + 1:
            raise ValueError(
                f"`n_action_steps` must be <= horizon - n_obs_steps + 1 = "
                f"{self.horizon - self.n_obs_steps + 1}, got {self.n_action_steps}"
            )
        downsampling = 2 ** len(self.down_dims)
        if self.horizon % downsampling:
            raise ValueError(
                f"`horizon` ({self.horizon}) must be a multiple of 2**len(down_dims) = {downsampling}"
            )
        if self.resize_shape is not None and (len(self.resize_shape) != 2 or min(self.resize_shape) < 1):
            raise ValueError(f"`resize_shape` must be (height, width) positive ints, got {self.resize_shape}")
        if not 0 < self.random_crop_min_scale <= 1:
            raise ValueError(
                "`random_crop_min_scale`: expected a fraction in (0, 1] (1: no crop), "
                f"got {self.random_crop_min_scale}"
            )
        for name in (
            "calibration_noise_rotation_deg",
            "calibration_noise_translation_mm",
            "calibration_noise_focal_pct",
            "calibration_noise_principal_px",
        ):
            if not getattr(self, name) >= 0:
                raise ValueError(f"`{name}`: expected a standard deviation >= 0, got {getattr(self, name)}")
        if not 0 <= self.camera_dropout < 1:
            raise ValueError(f"`camera_dropout`: expected a probability in [0, 1), got {self.camera_dropout}")
        if not 0 <= self.single_camera_rate <= 1:
            raise ValueError(
                f"`single_camera_rate`: expected a share in [0, 1], got {self.single_camera_rate}"
            )
        if not 0 <= self.camera_rotation_deg < 90:
            raise ValueError(
                f"`camera_rotation_deg`: expected an angle in [0, 90) degrees, got {self.camera_rotation_deg}"
            )
        if not self.position_shift_m >= 0:
            raise ValueError(
                f"`position_shift_m`: expected a half-width >= 0 (m), got {self.position_shift_m}"
            )
        for name in ("state_position_dims", "action_position_dims"):
            dims = tuple(getattr(self, name))
            if len(dims) != 2 or len(set(dims)) != 2 or not all(isinstance(i, int) and i >= 0 for i in dims):
                raise ValueError(f"`{name}`: expected two distinct indices >= 0 (x, y), got {dims}")
            setattr(self, name, dims)
        if not self.use_ofg:
            for name, off in OFG_ONLY_OPTIONS.items():
                if getattr(self, name) != off:
                    raise ValueError(
                        f"`{name}`: expected {off} (off) with use_ofg=false, got {getattr(self, name)}: it "
                        f"augments the images and calibrations the OFG fuses, and the 'w/o OFG' ablation "
                        f"has no OFG, so it would have no effect"
                    )
        if isinstance(self.frozen_modules, str):
            raise ValueError(
                f"`frozen_modules`: expected a list of {list(FREEZABLE)} (on the command line as JSON, "
                f"'[\"head\"]'), got the string {self.frozen_modules!r}"
            )
        self.frozen_modules = tuple(self.frozen_modules)
        unknown = [m for m in self.frozen_modules if m not in FREEZABLE]
        if unknown or len(set(self.frozen_modules)) == len(FREEZABLE):
            raise ValueError(
                f"`frozen_modules`: expected some of {list(FREEZABLE)} (not all: something must train), got "
                f"{list(self.frozen_modules)}"
            )
        self.volume_bounds = tuple(tuple(float(v) for v in b) for b in self.volume_bounds)
        self.volume_shape = tuple(int(n) for n in self.volume_shape)
        try:
            self.feature_volume  # noqa: B018  (validates bounds and shape)
        except ValueError as e:
            raise ValueError(f"`volume_bounds` / `volume_shape`: {e}") from e
        # Validated once, kept in the canonical JSON form that config.json stores.
        self.camera_calibration = {
            key: CameraCalibration.from_dict(calib, camera=key).to_dict()
            for key, calib in self.camera_calibration.items()
        }
        # A calibration file is read once, here, and merged; the saved config never refers to it again.
        self._calibration_overrides: dict[str, dict] = {}
        if self.calibration_path is not None:
            try:
                from_file = load_calibration_file(self.calibration_path)
            except CalibrationError as e:
                raise CalibrationError(f"`calibration_path`: {e}") from e
            self._calibration_overrides = {key: calib.to_dict() for key, calib in from_file.items()}
            self.camera_calibration.update(self._calibration_overrides)
            self.calibration_path = None

    def _select_cameras(self) -> None:
        """Restrict (or extend) the image inputs to ``cameras``; a camera the features do not list yet
        (evaluation on another view) gets the shape of the existing image features."""
        if self.cameras is None or not self.input_features:
            return
        images = self.image_features
        template = next(iter(images.values()), None)
        wanted = [image_key(c) for c in self.cameras]
        unknown = [k for k in wanted if k not in images and template is None]
        if unknown:
            raise ValueError(f"`cameras`: no image feature to take the shape of {unknown} from")
        others = {k: ft for k, ft in self.input_features.items() if ft.type is not FeatureType.VISUAL}
        self.input_features = {**others, **{k: images.get(k, template) for k in wanted}}

    @property
    def feature_volume(self) -> FeatureVolume:
        return FeatureVolume(bounds=self.volume_bounds, shape=self.volume_shape, pillar_axis=self.pillar_axis)

    def calibration(self, image_key: str) -> CameraCalibration:
        """The calibration of one image feature, or a clear error naming it."""
        if image_key not in self.camera_calibration:
            raise CalibrationError(
                f"{image_key}: no camera calibration in the policy config (calibrated cameras: "
                f"{sorted(self.camera_calibration) or 'none'}). Train on a dataset whose image features "
                f"carry info['calibration'], or set `camera_calibration`."
            )
        return CameraCalibration.from_dict(self.camera_calibration[image_key], camera=image_key)

    def set_dataset_feature_metadata(self, dataset_features: dict[str, dict[str, Any]]) -> None:
        """Called by LeRobot's ``make_policy`` with the dataset's features: take their calibrations.

        The calibration of every image feature of the dataset replaces what the config had (so
        fine-tuning a checkpoint on a dataset with new cameras uses the new calibrations), and the
        policy's image inputs become the dataset's image features: the OFG does not depend on the
        number or identity of cameras. The names of an ``observation.camera_visible`` column are taken too
        (``camera_visible_names``), and that column is kept out of the inputs, as the calibration columns.
        """
        image_keys = [
            k
            for k, ft in dataset_features.items()
            if k.startswith("observation.image") and ft.get("dtype") in ("video", "image")
        ]
        if self.cameras is not None:
            wanted = [image_key(c) for c in self.cameras]
            missing = [k for k in wanted if k not in image_keys]
            if missing:
                raise ValueError(f"`cameras`: {missing} not among the dataset's image features {image_keys}")
            image_keys = wanted
        # Per-frame columns win over a static calibration; a camera needs one or the other.
        self.frame_calibration = [
            k
            for k in image_keys
            if extrinsics_key(k) in dataset_features and intrinsics_key(k) in dataset_features
        ]
        # A calibration file that would be ignored (no camera in common, or a camera calibrated per frame)
        # is a mistake, not a preference.
        from_file = self._calibration_overrides
        if from_file and not set(from_file) & set(image_keys):
            raise CalibrationError(
                f"`calibration_path`: none of the file's cameras {sorted(from_file)} is an image feature of "
                f"the dataset that the policy uses {image_keys}, so the file would be ignored and the "
                f"dataset's calibration trained instead; key the file by these cameras (`<cam>` or "
                f"`observation.images.<cam>`)"
            )
        self._check_no_override_of_frame_calibration()
        self.camera_visible_names = _camera_visible_names(dataset_features, image_keys)
        # The "w/o OFG" ablation does not use calibration: keep whatever the dataset has.
        # A calibration file given with this config overrides the dataset's static calibration.
        self.camera_calibration = {
            k: from_file[k]
            if k in from_file
            else calibration_from_feature_info(k, dataset_features[k]).to_dict()
            for k in image_keys
            if (self.use_ofg and k not in self.frame_calibration)
            or k in from_file
            or CALIBRATION_INFO_KEY in (dataset_features[k].get("info") or {})
        }
        if self.input_features:
            policy_features = dataset_to_policy_features(dataset_features)
            dataset_images = {k: policy_features[k] for k in image_keys}
            others = {
                k: ft
                for k, ft in self.input_features.items()
                if ft.type is not FeatureType.VISUAL and not is_calibration_key(k) and k != CAMERA_VISIBLE_KEY
            }
            self.input_features = {**others, **dataset_images}

    def _check_no_override_of_frame_calibration(self) -> None:
        """Refuse a calibration file's entry for a camera calibrated per frame: the policy reads that
        camera's calibration from every frame's columns, so the entry would be silently ignored."""
        overridden = sorted(k for k in self._calibration_overrides if k in self.frame_calibration)
        if overridden:
            raise CalibrationError(
                f"`calibration_path`: the file calibrates {overridden}, but the policy reads their "
                f"calibration from every frame (`frame_calibration`: {self.frame_calibration}, from the "
                f"columns observation.extrinsics.<cam> / observation.intrinsics.<cam>), so the file's entry "
                f"would be ignored; remove {overridden} from the file"
            )

    def validate_features(self) -> None:
        self._select_cameras()
        self._check_no_override_of_frame_calibration()
        if not self.image_features:
            raise ValueError("OmniD needs at least one `observation.images.*` input feature.")
        if self.robot_state_feature is None:
            raise ValueError("OmniD needs `observation.state` among the input features.")
        env = {key: ft.shape for key, ft in self.input_features.items() if ft.type is FeatureType.ENV}
        if env and (list(env) != [OBS_ENV_STATE] or len(env[OBS_ENV_STATE]) != 1):
            raise ValueError(
                f"OmniD reads the env state from one vector feature `{OBS_ENV_STATE}` of shape (De,); "
                f"got the ENV input features {env}"
            )
        for key, ft in self.image_features.items():
            if len(ft.shape) != 3 or ft.shape[0] != 3:
                raise ValueError(f"{key}: expected an RGB image feature of shape (3, H, W), got {ft.shape}")
            if self.use_ofg and key not in self.frame_calibration:
                self.calibration(key)
        if not self.use_ofg and self.camera_visible_names is not None:
            raise ValueError(
                f"`camera_visible_names`: expected None with use_ofg=false, got {self.camera_visible_names} "
                f"(the dataset's `{CAMERA_VISIBLE_KEY}` column): the 'w/o OFG' ablation concatenates every "
                f"camera's features in a fixed order and cannot leave a hidden camera out"
            )
        if self.position_shift_m > 0:
            shifted = {
                "state_position_dims": self.robot_state_feature,
                "action_position_dims": self.action_feature,
            }
            for name, feature in shifted.items():
                if feature is not None and max(getattr(self, name)) >= feature.shape[0]:
                    raise ValueError(
                        f"`{name}`: expected indices below the feature's {feature.shape[0]} entries, got "
                        f"{getattr(self, name)}"
                    )
        if not self.use_ofg:
            shapes = {ft.shape for ft in self.image_features.values()}
            if len(shapes) > 1:
                raise ValueError(f"Without the OFG all images must share one shape, got {sorted(shapes)}")

    def get_optimizer_preset(self) -> AdamWConfig:
        return AdamWConfig(
            lr=self.optimizer_lr,
            betas=self.optimizer_betas,
            eps=self.optimizer_eps,
            weight_decay=self.optimizer_weight_decay,
        )

    def get_scheduler_preset(self) -> DiffuserSchedulerConfig:
        return DiffuserSchedulerConfig(name=self.scheduler_name, num_warmup_steps=self.scheduler_warmup_steps)

    @property
    def observation_delta_indices(self) -> list[int]:
        return list(range(1 - self.n_obs_steps, 1))

    @property
    def action_delta_indices(self) -> list[int]:
        return list(range(1 - self.n_obs_steps, 1 - self.n_obs_steps + self.horizon))

    @property
    def reward_delta_indices(self) -> None:
        return None


def _camera_visible_names(
    dataset_features: dict[str, dict[str, Any]], image_keys: list[str]
) -> list[str] | None:
    """The recorded cameras' names of the dataset's ``observation.camera_visible`` column (None without one),
    checked: one distinct name per value, and every camera the policy uses among them."""
    feature = dataset_features.get(CAMERA_VISIBLE_KEY)
    if feature is None:
        return None
    names, shape = feature.get("names"), tuple(feature.get("shape") or ())
    if (
        not isinstance(names, list | tuple)
        or len(shape) != 1
        or len(names) != shape[0]
        or len(set(names)) != len(names)
    ):
        raise ValueError(
            f"`{CAMERA_VISIBLE_KEY}`: expected a feature of shape (R,) whose names are the R distinct "
            f"recorded cameras, got shape {shape} and names {names!r}"
        )
    missing = [camera_name(k) for k in image_keys if camera_name(k) not in names]
    if missing:
        raise ValueError(
            f"`{CAMERA_VISIBLE_KEY}`: the policy's cameras {missing} are not among the column's cameras "
            f"{list(names)}, so whether an episode shows them is unknown"
        )
    return list(names)
