"""OmniD policy: shared ResNet -> Omni-Feature Generator -> LeRobot's conditional 1D UNet diffusion head.

Shape legend: B batch, T observation steps, S cameras, H W image, Da action dim, Ds state dim, De env state
dim (``observation.environment_state``, e.g. a task one-hot; absent unless the inputs have it), R recorded
cameras of an ``observation.camera_visible`` column.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping

import torch
import torch.nn.functional as F
from diffusers.schedulers.scheduling_ddim import DDIMScheduler
from diffusers.schedulers.scheduling_ddpm import DDPMScheduler
from huggingface_hub import ModelCard
from lerobot.configs.types import NormalizationMode
from lerobot.policies.diffusion.modeling_diffusion import DiffusionConditionalUnet1d, SpatialSoftmax
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.policies.utils import get_output_shape, populate_queues
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE
from torch import Tensor, nn

from lerobot_omnid.calibration.frame_columns import (
    extrinsics_from_column,
    extrinsics_key,
    frame_calibration_problem,
    intrinsics_from_column,
    intrinsics_key,
)
from lerobot_omnid.calibration.schema import (
    ASPECT_TOLERANCE,
    CalibrationError,
    CameraCalibration,
    camera_matrices,
)
from lerobot_omnid.camera_visibility import CAMERA_VISIBLE_KEY, visible_cameras
from lerobot_omnid.geometry import (
    axis_angle_to_matrix,
    crop_intrinsics,
    crop_theta,
    perturb_extrinsics,
    perturb_intrinsics,
    random_unit_vectors,
    resize_intrinsics,
    rotation_warp_grid,
    translate_world,
)
from lerobot_omnid.policy.backbone import ResNetFeatures
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.model_card import find_eval_results, omnid_card_section
from lerobot_omnid.policy.omni_feature_generator import OFGOutput, OmniFeatureGenerator

FRAME_MATRICES = ("omnid.pix_T_cam", "omnid.cam_T_world")
"""Keys of every frame's camera matrices among the stacked (and queued) inputs: (B, [T,] S, 3, 3) and 4x4,
for the backbone's input size, static and per-frame calibration alike."""

VISIBLE_CAMERAS = "omnid.visible_cameras"
"""Key of every frame's mask of the policy's cameras it shows among the stacked (and queued) inputs:
(B, [T,] S) bool, from ``observation.camera_visible``; absent when the batch has no such column."""


def camera_dropout_mask(
    batch_size: int,
    num_cameras: int,
    p: float,
    device: torch.device,
    single_rate: float = 0.0,
    available: Tensor | None = None,
) -> Tensor:
    """(B, S) bool: each camera kept with probability 1 - p, and at least one (a random one) per sample;
    a share ``single_rate`` of the samples then keeps exactly that one camera.

    ``available`` (B, S) bool, at least one per sample (the cameras each sample shows,
    ``observation.camera_visible``): only those are kept, and the one kept for sure is drawn among them.
    """
    keep = torch.rand(batch_size, num_cameras, device=device) >= p
    if available is None:
        pick = torch.randint(num_cameras, (batch_size,), device=device)
    else:
        keep = keep & available
        pick = torch.rand(batch_size, num_cameras, device=device).masked_fill(~available, -1.0).argmax(dim=-1)
    one = F.one_hot(pick, num_cameras).bool()
    single = torch.rand(batch_size, 1, device=device) < single_rate
    return torch.where(single, one, keep | one)


def resize_images(images: Tensor, image_hw: tuple[int, int]) -> Tensor:
    """(..., 3, H, W) -> (..., 3, *image_hw), whole images (antialiased bilinear); unchanged at that size."""
    if tuple(images.shape[-2:]) == image_hw:
        return images
    x = F.interpolate(
        images.flatten(0, -4), size=image_hw, mode="bilinear", align_corners=False, antialias=True
    )
    return x.unflatten(0, images.shape[:-3])


def _frame_name(batch: Mapping[str, Tensor], index: tuple[int, ...], lead: torch.Size) -> str:
    """Which frame ``index`` (into the (B, [T]) leading dims) is: the sample and observation step, and its
    episode and frame when the batch has LeRobot's ``episode_index`` / ``frame_index`` (those of each
    sample's last step; earlier steps are earlier frames of the episode, its first repeated as padding)."""
    parts = [f"batch sample {index[0]}"]
    steps_back = 0
    if len(lead) > 1:
        parts.append(f"observation step {index[1]} of {lead[1]}")
        steps_back = lead[1] - 1 - index[1]
    if "episode_index" in batch:
        parts.append(f"episode {int(batch['episode_index'].reshape(lead[0], -1)[index[0], -1])}")
    if "frame_index" in batch:
        frame = int(batch["frame_index"].reshape(lead[0], -1)[index[0], -1]) - steps_back
        parts.append(f"frame {max(frame, 0)}")
    return ", ".join(parts)


def normalised_per_metre(
    feature: str, stats: Mapping[str, Tensor] | None, dims: tuple[int, ...], mode: NormalizationMode
) -> Tensor | None:
    """(len(dims),) normalised units per metre of ``feature``'s ``dims`` under its normalisation ``mode``
    (LeRobot's: MIN_MAX maps ``[min, max]`` to ``[-1, 1]``, MEAN_STD divides by ``std``), from its dataset
    ``stats``; None when ``stats`` are needed and missing."""
    if mode is NormalizationMode.IDENTITY:
        return torch.ones(len(dims))
    if stats is None:
        return None
    index = list(dims)
    if mode is NormalizationMode.MIN_MAX:
        width = (
            torch.as_tensor(stats["max"], dtype=torch.float32)[index]
            - torch.as_tensor(stats["min"], dtype=torch.float32)[index]
        )
        return 2 / width.clamp(min=1e-8)
    if mode is NormalizationMode.MEAN_STD:
        return 1 / torch.as_tensor(stats["std"], dtype=torch.float32)[index].clamp(min=1e-8)
    raise ValueError(
        f"`position_shift_m`: expected MIN_MAX, MEAN_STD or IDENTITY normalisation of `{feature}`, got {mode}"
    )


def _sample_visibility(visible: Tensor) -> Tensor:
    """(B, T, S) cameras each observation step shows -> (B, S) cameras each sample fuses: those that every
    step shows. One set per sample, as camera dropout draws it: every step's plane is lifted from the same
    cameras. Steps of one sample disagree only where the column changes within an episode (a window never
    spans two episodes); a camera hidden at any of them is then left out, since hidden means the camera is
    not to be seen."""
    per_sample = visible.all(dim=1)
    blind = (~per_sample.any(dim=-1)).nonzero()[:, 0].tolist()
    if blind:
        raise ValueError(
            f"`{CAMERA_VISIBLE_KEY}`: batch samples {blind} show none of the policy's cameras at every "
            f"observation step (each step shows some, but not the same); a sample fuses only the cameras "
            f"that all its steps show, and must keep at least one"
        )
    return per_sample


class OmniDPolicy(PreTrainedPolicy):
    """OmniD (Mao et al., 2025): multi-view BEV features by deformable attention + diffusion action head.

    The cameras used are ``config.image_features``; each needs an entry in ``config.camera_calibration``.
    The model itself does not depend on which or how many cameras there are. With an
    ``observation.environment_state`` input (``config.env_state_feature``), it conditions on it at every
    observation step, as LeRobot's DiffusionPolicy does.
    """

    config_class = OmniDConfig
    name = "omnid"

    def __init__(self, config: OmniDConfig, **kwargs) -> None:
        """``kwargs``: ``dataset_stats`` (from ``make_policy``) gives ``position_shift_m`` its metres in
        normalised units; otherwise normalisation lives in the processors and calibration in the config."""
        super().__init__(config)
        config.validate_features()
        self.config = config
        self.model = OmniDModel(config)
        # position_shift_m in the normalised units of the state's and the action's TCP x, y (empty: unknown).
        self.register_buffer("state_shift_scale", torch.zeros(0), persistent=False)
        self.register_buffer("action_shift_scale", torch.zeros(0), persistent=False)
        self._shift_reach: float | None = None  # the largest normalised action |x|, |y| a shift asks for
        if config.position_shift_m > 0:
            self._set_shift_scales(kwargs.get("dataset_stats"))
        # The cameras' matrices for the backbone's input size: parsed from the config once, kept as buffers
        # (they follow .to(device); not saved, config.json holds the calibration), rebuilt only when the
        # calibration, the cameras or the input size change.
        self.register_buffer("pix_T_cam", torch.zeros(0, 3, 3), persistent=False)
        self.register_buffer("cam_T_world", torch.zeros(0, 4, 4), persistent=False)
        self._calibrations: dict[str, CameraCalibration] = {}
        self._matrices_key: tuple | None = None
        self._checked_sizes: tuple | None = None  # the per-camera image sizes last found consistent
        if config.use_ofg:
            static = [key for key in self.camera_keys if key not in config.frame_calibration]
            self._calibrations = {key: config.calibration(key) for key in static}
        self.reset()

    def generate_model_card(self, *args, cfg=None, **kwargs) -> ModelCard:
        """LeRobot's card plus the cameras, their calibration and the evaluations found in the run."""
        card = super().generate_model_card(*args, cfg=cfg, **kwargs)
        results = find_eval_results(cfg.output_dir) if cfg is not None and cfg.output_dir else {}
        card.content = card.content + omnid_card_section(self.config, results)
        return card

    def get_optim_params(self) -> list[nn.Parameter]:
        """The trained weights: all but those of ``config.frozen_modules``."""
        return [p for p in self.model.parameters() if p.requires_grad]

    def reset(self) -> None:
        """Clear observation and action queues. Called on ``env.reset()``."""
        observed = (
            OBS_STATE,
            OBS_IMAGES,
            *((*FRAME_MATRICES, VISIBLE_CAMERAS) if self.config.use_ofg else ()),
            *((OBS_ENV_STATE,) if self.config.env_state_feature else ()),
        )
        self._queues = {key: deque(maxlen=self.config.n_obs_steps) for key in observed}
        self._queues[ACTION] = deque(maxlen=self.config.n_action_steps)

    @property
    def camera_keys(self) -> list[str]:
        return list(self.config.image_features)

    def _calibration(self, key: str) -> CameraCalibration:
        if key not in self._calibrations:
            self.config.calibration(key)  # raises the error that names the camera and the calibrated ones
        return self._calibrations[key]

    def set_calibration(self, calibrations: Mapping[str, CameraCalibration]) -> None:
        """Replace the calibration of some cameras (keyed by image feature key), in the config too.

        Use this, not ``config.camera_calibration``, on a policy that exists: its matrices are built from
        the calibrations parsed here. A camera calibrated per frame (``config.frame_calibration``) is
        refused: its frames' own calibration would win, and the one given here would never be used.
        """
        per_frame = sorted(k for k in calibrations if k in self.config.frame_calibration)
        if per_frame:
            raise CalibrationError(
                f"set_calibration: {per_frame} are calibrated per frame (`frame_calibration`), from the "
                f"columns of every observation; a static calibration for them would never be used. Give "
                f"the calibration in those columns instead."
            )
        for key, calib in calibrations.items():
            calib.validate(key)
            self.config.camera_calibration[key] = calib.to_dict()
        self._calibrations.update(calibrations)
        self._matrices_key = self._checked_sizes = None

    def camera_matrices(self, batch_size: int, image_hw: tuple[int, int]) -> tuple[Tensor, Tensor]:
        """Calibration of ``camera_keys`` for the backbone's input, broadcast to the batch.

        Args:
            batch_size: B.
            image_hw: (H, W) of the images given to the policy; the backbone sees ``config.resize_shape``
                when it is set, else this size.
        Returns:
            pix_T_cam (B, S, 3, 3) for the backbone's input size and cam_T_world (B, S, 4, 4).
        """
        input_hw = tuple(self.config.resize_shape or image_hw)
        key = (tuple(self.camera_keys), input_hw)
        S = len(self.camera_keys)
        if key != self._matrices_key:
            # Cameras calibrated per frame have no static matrices: identity placeholders, replaced by
            # every frame's own in frame_matrices.
            static = [i for i, k in enumerate(self.camera_keys) if k not in self.config.frame_calibration]
            pix_T_cam, cam_T_world = torch.eye(3).repeat(S, 1, 1), torch.eye(4).repeat(S, 1, 1)
            if static:
                pix_T_cam[static], cam_T_world[static] = camera_matrices(
                    [self._calibration(self.camera_keys[i]) for i in static], [input_hw] * len(static)
                )
            device = self.pix_T_cam.device
            self.pix_T_cam, self.cam_T_world = pix_T_cam.to(device), cam_T_world.to(device)
            self._matrices_key = key
        return (
            self.pix_T_cam.expand(batch_size, S, 3, 3),
            self.cam_T_world.expand(batch_size, S, 4, 4),
        )

    def _stack_inputs(self, batch: dict[str, Tensor], time_dim: bool) -> dict[str, Tensor]:
        """Validate the inputs and stack the cameras: images (B, [T,] S, 3, H, W), state (B, [T,] Ds), when
        the policy has one the env state (B, [T,] De) and, when the batch has ``observation.camera_visible``,
        the cameras each frame shows (B, [T,] S)."""
        image_ndim = 5 if time_dim else 4
        if OBS_STATE not in batch:
            raise KeyError(f"`{OBS_STATE}` is missing from the batch (keys: {sorted(batch)})")
        state = batch[OBS_STATE]
        if state.ndim != image_ndim - 2:
            raise ValueError(f"`{OBS_STATE}`: expected {image_ndim - 2} dims, got shape {tuple(state.shape)}")
        if not torch.isfinite(state).all():
            raise ValueError(f"`{OBS_STATE}` contains NaN or infinite values")
        images = []
        for key in self.camera_keys:
            if key not in batch:
                raise KeyError(f"`{key}` is missing from the batch (keys: {sorted(batch)})")
            img = batch[key]
            if time_dim and img.ndim == 4 and self.config.n_obs_steps == 1:
                img = img.unsqueeze(1)
            expected = "(B, T, 3, H, W)" if time_dim else "(B, 3, H, W)"
            if img.ndim != image_ndim or img.shape[-3] != 3:
                raise ValueError(f"`{key}`: expected images of shape {expected}, got {tuple(img.shape)}")
            if not torch.isfinite(img).all():
                raise ValueError(f"`{key}` contains NaN or infinite values")
            images.append(img)
        sizes = tuple(tuple(img.shape[-2:]) for img in images)
        if self.config.use_ofg:
            self._check_image_sizes(sizes)
        if len(set(sizes)) > 1:
            if self.config.resize_shape is None:
                found = ", ".join(f"{k} {h}x{w}" for k, (h, w) in zip(self.camera_keys, sizes, strict=True))
                raise ValueError(
                    f"All cameras must have one image size unless `resize_shape` is set, got {found}"
                )
            images = [resize_images(img, tuple(self.config.resize_shape)) for img in images]
        stacked = {OBS_STATE: state, OBS_IMAGES: torch.stack(images, dim=-4)}
        if self.config.env_state_feature:
            stacked[OBS_ENV_STATE] = self._env_state(batch, state.shape[:-1])
        if CAMERA_VISIBLE_KEY in batch:
            stacked[VISIBLE_CAMERAS] = self._visible_cameras(batch, state.shape[:-1])
        if self.config.use_ofg:
            stacked.update(zip(FRAME_MATRICES, self.frame_matrices(batch, sizes), strict=True))
        return stacked

    def _env_state(self, batch: dict[str, Tensor], lead: torch.Size) -> Tensor:
        """``observation.environment_state`` of the batch, (*lead, De), checked."""
        if OBS_ENV_STATE not in batch:
            raise KeyError(
                f"`{OBS_ENV_STATE}` is missing from the batch: the policy was made with it (the omnid envs' "
                f"task one-hot: --env.task_onehot=true); keys: {sorted(batch)}"
            )
        env_state = batch[OBS_ENV_STATE]
        expected = (*lead, self.config.env_state_feature.shape[0])
        if tuple(env_state.shape) != expected:
            raise ValueError(f"`{OBS_ENV_STATE}`: expected shape {expected}, got {tuple(env_state.shape)}")
        if not torch.isfinite(env_state).all():
            raise ValueError(f"`{OBS_ENV_STATE}` contains NaN or infinite values")
        return env_state

    def _visible_cameras(self, batch: dict[str, Tensor], lead: torch.Size) -> Tensor:
        """(*lead, S) bool: which of the policy's cameras each frame shows, from the batch's
        ``observation.camera_visible`` (*lead, R) over the recorded cameras ``config.camera_visible_names``;
        every frame must show at least one."""
        names = self.config.camera_visible_names
        if names is None:
            raise ValueError(
                f"`{CAMERA_VISIBLE_KEY}` is in the batch, but the policy does not know which recorded "
                f"cameras its values are for: `camera_visible_names` is None (the policy was not made from a "
                f"dataset with that column); set it to the column feature's names"
            )
        column = batch[CAMERA_VISIBLE_KEY]
        if tuple(column.shape) != (*lead, len(names)):
            raise ValueError(
                f"`{CAMERA_VISIBLE_KEY}`: expected shape {(*lead, len(names))} (one value per recorded "
                f"camera {names}), got {tuple(column.shape)}"
            )
        visible = visible_cameras(column, names, self.camera_keys)
        blind = ~visible.any(dim=-1)
        if blind.any():
            index = tuple(int(i) for i in blind.nonzero()[0])
            raise ValueError(
                f"`{CAMERA_VISIBLE_KEY}`: {_frame_name(batch, index, lead)} shows none of the policy's "
                f"cameras {self.camera_keys} (its column over {names}: {column[index].tolist()}); a sample "
                f"must keep at least one camera"
            )
        return visible

    def frame_matrices(
        self, batch: dict[str, Tensor], sizes: tuple[tuple[int, int], ...]
    ) -> tuple[Tensor, Tensor]:
        """Every frame's calibration, the one path from calibration to the OFG: the columns of the cameras in
        ``config.frame_calibration`` (checked frame by frame), the static matrices for the others.

        Args:
            batch: the policy's input, with ``observation.state`` (B, [T,] Ds) and, for each camera
                calibrated per frame, ``observation.extrinsics.<cam>`` (B, [T,] 16) and
                ``observation.intrinsics.<cam>`` (B, [T,] 9), K for that camera's image size in the batch.
            sizes: each camera's image size in the batch.
        Returns:
            pix_T_cam (B, [T,] S, 3, 3) for the backbone's input size and cam_T_world (B, [T,] S, 4, 4).
        """
        input_hw = tuple(self.config.resize_shape or sizes[0])
        lead = batch[OBS_STATE].shape[:-1]  # B, [T]
        static = self.camera_matrices(1, input_hw)  # 1, S, ...
        pix_T_cam, cam_T_world = (m[0].expand(*lead, *m.shape[1:]) for m in static)  # B, [T,] S, ...
        per_frame = [i for i, key in enumerate(self.camera_keys) if key in self.config.frame_calibration]
        if not per_frame:
            return pix_T_cam, cam_T_world
        pix_T_cam, cam_T_world = pix_T_cam.clone(), cam_T_world.clone()
        for i in per_frame:
            K, T = self._frame_columns(batch, self.camera_keys[i], lead)
            pix_T_cam[..., i, :, :] = resize_intrinsics(K.to(pix_T_cam.dtype), sizes[i], input_hw)
            cam_T_world[..., i, :, :] = T.to(cam_T_world.dtype)
        return pix_T_cam, cam_T_world

    def _frame_columns(self, batch: dict[str, Tensor], key: str, lead: torch.Size) -> tuple[Tensor, Tensor]:
        """K (*lead, 3, 3) and T_cam_world (*lead, 4, 4) of camera ``key`` from its columns, every frame
        checked like a static calibration (a proper K, a rigid transform)."""
        columns = []
        for column_key, size in ((intrinsics_key(key), 9), (extrinsics_key(key), 16)):
            if column_key not in batch:
                raise KeyError(
                    f"`{column_key}` is missing from the batch: {key} is calibrated per frame "
                    f"(`frame_calibration`); keys: {sorted(batch)}"
                )
            value = batch[column_key]
            if tuple(value.shape) != (*lead, size):
                raise ValueError(f"`{column_key}`: expected shape {(*lead, size)}, got {tuple(value.shape)}")
            columns.append(value)
        K, T = intrinsics_from_column(columns[0]), extrinsics_from_column(columns[1])
        problem = frame_calibration_problem(K, T)
        if problem is not None:
            index, reason = problem
            raise CalibrationError(
                f"{key}: the per-frame calibration of {_frame_name(batch, index, lead)} is not a camera's: "
                f"{reason} (columns `{intrinsics_key(key)}`, `{extrinsics_key(key)}`; "
                f"K = {K[index].tolist()}, T_cam_world = {T[index].tolist()})"
            )
        return K, T

    def _check_image_sizes(self, sizes: tuple[tuple[int, int], ...]) -> None:
        """Each camera's images must be its calibrated image resized uniformly, unless they were stretched.

        A 16:9 image against a 4:3 calibration is another sensor mode (a crop), for which a rescaled K is
        wrong; only ``images_stretched=True`` says the images are the calibrated ones stretched.
        """
        if sizes == self._checked_sizes or self.config.images_stretched:
            return
        for key, (h, w) in zip(self.camera_keys, sizes, strict=True):
            if key in self.config.frame_calibration:
                continue  # each frame's K is for the image that comes with it
            calib_h, calib_w = self._calibration(key).image_size
            if abs((h / calib_h) / (w / calib_w) - 1) > ASPECT_TOLERANCE:
                raise CalibrationError(
                    f"{key}: images of {h}x{w} (height x width) for a calibration of {calib_h}x{calib_w}: "
                    f"another aspect ratio, so K cannot be rescaled (a camera in another sensor mode crops). "
                    f"Calibrate the camera at this size, or set `images_stretched=true` if the images are "
                    f"the calibrated ones stretched to this size."
                )
        self._checked_sizes = sizes

    def _condition(self, stacked: dict[str, Tensor], augment: bool = False) -> Tensor:
        images, env_state = stacked[OBS_IMAGES], stacked.get(OBS_ENV_STATE)
        if not self.config.use_ofg:
            return self.model.global_condition(images, stacked[OBS_STATE], None, None, env_state=env_state)
        pix_T_cam, cam_T_world = (stacked[k] for k in FRAME_MATRICES)  # B, T, S, ...
        camera_mask = _sample_visibility(stacked[VISIBLE_CAMERAS]) if VISIBLE_CAMERAS in stacked else None
        if augment:
            images, pix_T_cam, cam_T_world, camera_mask = self._augment(
                images, pix_T_cam, cam_T_world, camera_mask
            )
        return self.model.global_condition(
            images, stacked[OBS_STATE], pix_T_cam, cam_T_world, camera_mask, env_state=env_state
        )

    def _augment(
        self, images: Tensor, pix_T_cam: Tensor, cam_T_world: Tensor, visible: Tensor | None = None
    ) -> tuple[Tensor, Tensor, Tensor, Tensor | None]:
        """The training-time options that keep images and calibration consistent: camera rotation, crop,
        calibration noise, camera dropout (among the ``visible`` (B, S) cameras of each sample, when given;
        the returned mask is ``visible`` itself without dropout). Geometry in full precision (autocast off):
        see the OFG."""
        camera_mask = visible
        with torch.autocast(images.device.type, enabled=False):
            if self.config.camera_rotation_deg > 0:
                images, cam_T_world = self._rotate_cameras(images, pix_T_cam.float(), cam_T_world.float())
            if self.config.random_crop_min_scale < 1:
                images, pix_T_cam = self._random_crop(images, pix_T_cam)
            pix_T_cam, cam_T_world = self._calibration_noise(pix_T_cam.float(), cam_T_world.float())
        if self.config.camera_dropout > 0 or self.config.single_camera_rate > 0:
            B, S = images.shape[0], images.shape[2]  # images: B, T, S, 3, H, W
            camera_mask = camera_dropout_mask(
                B, S, self.config.camera_dropout, images.device, self.config.single_camera_rate, visible
            )
        return images, pix_T_cam, cam_T_world, camera_mask

    def _calibration_noise(self, pix_T_cam: Tensor, cam_T_world: Tensor) -> tuple[Tensor, Tensor]:
        """The training-time calibration noise of the config, per sample and camera (every observation
        step of a sample gets the same): pix_T_cam (B, [T,] S, 3, 3), cam_T_world (B, [T,] S, 4, 4)."""
        c = self.config
        B, S = cam_T_world.shape[0], cam_T_world.shape[-3]
        like = {"dtype": cam_T_world.dtype, "device": cam_T_world.device}
        per_step = (slice(None), None) if cam_T_world.ndim == 5 else (slice(None),)  # broadcast over T
        if c.calibration_noise_rotation_deg > 0 or c.calibration_noise_translation_mm > 0:
            rotvec = torch.randn(B, S, 3, **like) * math.radians(c.calibration_noise_rotation_deg)
            angle = rotvec.norm(dim=-1)
            rotation = axis_angle_to_matrix(rotvec / angle.clamp(min=1e-12)[..., None], angle)
            shift = torch.randn(B, S, 3, **like) * (c.calibration_noise_translation_mm / 1000)
            cam_T_world = perturb_extrinsics(cam_T_world, rotation[per_step], shift[per_step])
        if c.calibration_noise_focal_pct > 0 or c.calibration_noise_principal_px > 0:
            scale = 1 + torch.randn(B, S, **like) * (c.calibration_noise_focal_pct / 100)
            shift = torch.randn(B, S, 2, **like) * c.calibration_noise_principal_px
            pix_T_cam = perturb_intrinsics(pix_T_cam, scale[per_step], shift[per_step])
        return pix_T_cam, cam_T_world

    def _rotate_cameras(
        self, images: Tensor, pix_T_cam: Tensor, cam_T_world: Tensor, rotation: Tensor | None = None
    ) -> tuple[Tensor, Tensor]:
        """``camera_rotation_deg``: each sample's cameras turned about their optical centres, their images
        warped to the turned views and their extrinsics turned with them.

        Args:
            images: (B, T, S, 3, H, W).
            pix_T_cam: (B, S, 3, 3), or (B, T, S, 3, 3) calibrated per frame, for the backbone's input size.
            cam_T_world: (B, S, 4, 4), or (B, T, S, 4, 4).
            rotation: (B, S, 3, 3), the same for every observation step; None draws each uniformly up to
                ``camera_rotation_deg`` about a random axis.
        Returns:
            The warped images (B, T, S, 3, H, W) and the turned cam_T_world.
        """
        B, T, S, _, H, W = images.shape
        if rotation is None:
            like = {"dtype": cam_T_world.dtype, "device": cam_T_world.device}
            angle = torch.rand(B, S, **like) * math.radians(self.config.camera_rotation_deg)
            rotation = axis_angle_to_matrix(random_unit_vectors((B, S), **like), angle)
        if pix_T_cam.ndim == 5:
            rotation = rotation[:, None].expand(B, T, S, 3, 3)
        input_hw = tuple(self.config.resize_shape or (H, W))
        grid = rotation_warp_grid(pix_T_cam, rotation, (H, W), input_hw)  # B, [T,] S, H, W, 2
        grid = grid[:, None].expand(B, T, S, H, W, 2) if grid.ndim == 5 else grid
        x = F.grid_sample(
            images.flatten(0, 2),
            grid.reshape(B * T * S, H, W, 2).to(images.dtype),
            mode="bilinear",
            padding_mode="zeros",
            align_corners=False,
        )
        still = torch.zeros(*rotation.shape[:-2], 3, dtype=cam_T_world.dtype, device=cam_T_world.device)
        return x.view_as(images), perturb_extrinsics(cam_T_world, rotation, still)

    def _random_crop(self, images: Tensor, pix_T_cam: Tensor) -> tuple[Tensor, Tensor]:
        """Geometric augmentation that keeps the calibration: per sample and camera (the same for every
        observation step) a random square-ratio crop of ``random_crop_min_scale``..1 of each side, resized
        back, with K moved with it.

        Args:
            images: (B, T, S, 3, H, W).
            pix_T_cam: (B, S, 3, 3), or (B, T, S, 3, 3) calibrated per frame, for the backbone's input size.
        """
        B, T, S = images.shape[:3]
        scale = torch.empty(B, S, device=images.device).uniform_(self.config.random_crop_min_scale, 1.0)
        left, top = (torch.rand(B, S, device=images.device) * (1 - scale) for _ in range(2))
        box = torch.stack([left, top, scale, scale], dim=-1)  # B, S, 4
        theta = crop_theta(box).to(images.dtype)[:, None].expand(B, T, S, 2, 3)  # B, T, S, 2, 3
        x = images.flatten(0, 2)  # B*T*S, 3, H, W
        grid = F.affine_grid(theta.reshape(-1, 2, 3), list(x.shape), align_corners=False)
        x = F.grid_sample(x, grid, mode="bilinear", padding_mode="border", align_corners=False)
        input_hw = tuple(self.config.resize_shape or images.shape[-2:])
        if pix_T_cam.ndim == 5:
            box = box[:, None]  # B, 1, S, 4: one crop for every observation step
        return x.view_as(images), crop_intrinsics(pix_T_cam, box, input_hw)

    def _set_shift_scales(self, stats: Mapping[str, Mapping[str, Tensor]] | None) -> None:
        """``position_shift_m``'s normalised units per metre of the state's and the action's TCP x, y, from
        the dataset's statistics (left empty without them: a policy loaded for inference needs none)."""
        c = self.config
        modes = c.normalization_mapping
        scales = [
            normalised_per_metre(key, stats.get(key) if stats else None, dims, NormalizationMode(modes[kind]))
            for key, dims, kind in (
                (OBS_STATE, c.state_position_dims, "STATE"),
                (ACTION, c.action_position_dims, "ACTION"),
            )
        ]
        if None not in scales:
            self.state_shift_scale, self.action_shift_scale = scales
            self._shift_reach = 1 + c.position_shift_m * float(scales[1].max())  # once, not per step

    def _check_shift_reach(self) -> None:
        """Training with a shift needs the units, and a head that can command the shifted action targets."""
        c = self.config
        reach = self._shift_reach
        if reach is None:
            raise ValueError(
                "`position_shift_m` > 0 needs the dataset's statistics to convert metres to normalised "
                "units: make the policy with `dataset_stats` (lerobot-train's make_policy passes them)"
            )
        clipped = NormalizationMode(c.normalization_mapping["ACTION"]) is NormalizationMode.MIN_MAX
        if clipped and c.clip_sample and c.clip_sample_range < reach:
            raise ValueError(
                f"`position_shift_m` = {c.position_shift_m} m moves the normalised action's x, y by up "
                f"to {reach - 1:.2f} (this dataset's action range), beyond `clip_sample_range` = "
                f"{c.clip_sample_range}: the head could never command the shifted targets near the "
                f"range's edges; set clip_sample_range >= {reach:.2f} (or clip_sample=false)"
            )

    def _shift_positions(
        self, stacked: dict[str, Tensor], actions: Tensor, shift_xy: Tensor | None = None
    ) -> tuple[dict[str, Tensor], Tensor]:
        """``position_shift_m``: the whole scene translated by a planar shift per sample.

        Args:
            stacked: the stacked inputs, state (B, T, Ds) normalised and cam_T_world (B, T, S, 4, 4).
            actions: (B, horizon, Da), normalised.
            shift_xy: (B, 2) metres along world x, y; None draws it uniformly in +-``position_shift_m``.
        Returns:
            ``stacked`` with its state's TCP x, y and its cameras moved by the shift, and the actions' TCP
            x, y moved by it.
        """
        self._check_shift_reach()
        B = actions.shape[0]
        if shift_xy is None:
            shift_xy = (torch.rand(B, 2, device=actions.device) * 2 - 1) * self.config.position_shift_m
        stacked = dict(stacked)
        state = stacked[OBS_STATE].clone()
        state[..., list(self.config.state_position_dims)] += shift_xy[:, None] * self.state_shift_scale
        stacked[OBS_STATE] = state
        actions = actions.clone()
        actions[..., list(self.config.action_position_dims)] += shift_xy[:, None] * self.action_shift_scale
        cam_T_world = stacked[FRAME_MATRICES[1]].float()
        shift = F.pad(shift_xy, (0, 1)).float()  # B, 3: nothing moves in z
        lead = (B,) + (1,) * (cam_T_world.ndim - 3)
        with torch.autocast(cam_T_world.device.type, enabled=False):  # geometry in full precision
            stacked[FRAME_MATRICES[1]] = translate_world(
                cam_T_world, shift.view(*lead, 3).expand(*cam_T_world.shape[:-2], 3)
            )
        return stacked, actions

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], noise: Tensor | None = None) -> Tensor:
        """Predict ``n_action_steps`` actions (B, n_action_steps, Da) from the queued observations, or from
        a batch with a time dimension when the queues are empty (offline use)."""
        if len(self._queues[OBS_STATE]) > 0:
            # A queue stays empty for an input the observations lack (the env sends no camera_visible).
            stacked = {k: torch.stack(list(q), dim=1) for k, q in self._queues.items() if k != ACTION and q}
        else:
            stacked = self._stack_inputs(batch, time_dim=True)
        return self.model.generate_actions(self._condition(stacked), noise=noise)

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], noise: Tensor | None = None) -> Tensor:
        """One action (B, Da) for the current observation (images (B, 3, H, W), state (B, Ds), env state
        (B, De) when the policy has one).

        ``n_obs_steps`` observations are queued; a chunk of ``horizon`` actions is generated whenever
        the action queue is empty and its ``n_action_steps`` first actions from the current step are
        executed (same schedule as LeRobot's DiffusionPolicy).
        """
        stacked = self._stack_inputs(batch, time_dim=False)
        self._queues = populate_queues(self._queues, stacked)
        if len(self._queues[ACTION]) == 0:
            actions = self.predict_action_chunk(batch, noise=noise)
            self._queues[ACTION].extend(actions.transpose(0, 1))
        return self._queues[ACTION].popleft()

    def forward(self, batch: dict[str, Tensor]) -> tuple[Tensor, None]:
        """Diffusion loss of a training batch: images (B, T, 3, H, W), state (B, T, Ds), env state (B, T, De)
        when the policy has one, action (B, horizon, Da), action_is_pad (B, horizon)."""
        stacked = self._stack_inputs(batch, time_dim=True)
        if ACTION not in batch:
            raise KeyError(f"`{ACTION}` is missing from the training batch (keys: {sorted(batch)})")
        pad = batch.get("action_is_pad") if self.config.do_mask_loss_for_padding else None
        actions = batch[ACTION]
        if self.training and self.config.position_shift_m > 0:
            stacked, actions = self._shift_positions(stacked, actions)
        condition = self._condition(stacked, augment=self.training)
        return self.model.compute_loss(condition, actions, pad), None


class OmniDModel(nn.Module):
    """The maths: observation encoder (backbone + OFG, or the "w/o OFG" pooling) and diffusion head."""

    def __init__(self, config: OmniDConfig) -> None:
        super().__init__()
        self.config = config
        self.backbone = ResNetFeatures(
            config.vision_backbone,
            config.backbone_layer,
            config.use_group_norm,
            config.pretrained_backbone_weights,
            gradient_checkpointing=config.checkpoint_backbone,
        )
        if config.use_ofg:
            self.ofg = OmniFeatureGenerator(
                config, self.backbone.out_channels, self.backbone.stride, self.backbone.offset
            )
            image_cond_dim = self.ofg.out_dim
        else:
            # "w/o OFG" ablation: per-camera spatial-softmax keypoints, concatenated in camera order.
            image_shape = next(iter(config.image_features.values())).shape
            input_hw = config.resize_shape or tuple(image_shape[1:])
            feature_shape = get_output_shape(self.backbone, (1, 3, *input_hw))[1:]
            num_kp = config.spatial_softmax_num_keypoints
            self.pool = nn.Sequential(
                SpatialSoftmax(feature_shape, num_kp=num_kp),
                nn.Flatten(),
                nn.Linear(num_kp * 2, num_kp * 2),
                nn.ReLU(),
            )
            image_cond_dim = num_kp * 2 * len(config.image_features)
        self.image_cond_dim = image_cond_dim
        # Every observation step carries the state and the env state (if any), as in LeRobot's DP.
        state_dim = config.robot_state_feature.shape[0]
        if config.env_state_feature:
            state_dim += config.env_state_feature.shape[0]
        image_steps = 1 if config.fuse_last_step_only else config.n_obs_steps
        self.global_cond_dim = image_cond_dim * image_steps + state_dim * config.n_obs_steps
        self.unet = DiffusionConditionalUnet1d(config, global_cond_dim=self.global_cond_dim)
        scheduler_cls = DDPMScheduler if config.noise_scheduler_type == "DDPM" else DDIMScheduler
        self.noise_scheduler = scheduler_cls(
            num_train_timesteps=config.num_train_timesteps,
            beta_start=config.beta_start,
            beta_end=config.beta_end,
            beta_schedule=config.beta_schedule,
            clip_sample=config.clip_sample,
            clip_sample_range=config.clip_sample_range,
            prediction_type=config.prediction_type,
        )
        self.num_inference_steps = config.num_inference_steps or config.num_train_timesteps
        for name in config.frozen_modules:
            self.part(name).requires_grad_(False)

    def part(self, name: str) -> nn.Module:
        """One of the parts ``frozen_modules`` names: "backbone", "ofg" (the keypoint pooling without an
        OFG) or "head"."""
        parts = {"backbone": self.backbone, "ofg": self.ofg if self.config.use_ofg else self.pool}
        return {**parts, "head": self.unet}[name]

    def train(self, mode: bool = True) -> OmniDModel:
        """As ``nn.Module.train``, but frozen parts stay in eval mode (their normalisation statistics and
        dropout as at inference)."""
        super().train(mode)
        for name in self.config.frozen_modules:
            self.part(name).eval()
        return self

    def encode_images(
        self,
        images: Tensor,
        pix_T_cam: Tensor | None,
        cam_T_world: Tensor | None,
        camera_mask: Tensor | None = None,
    ) -> tuple[Tensor, OFGOutput | None]:
        """Image condition of each observation step.

        Args:
            images: (B, T, S, 3, H, W) in [0, 1].
            pix_T_cam: (B, S, 3, 3) intrinsics per sample and camera for the backbone's input size
                (``config.resize_shape``, else (H, W)), or (B, T, S, 3, 3) per observation step; None
                without the OFG.
            cam_T_world: (B, S, 4, 4) extrinsics per sample and camera, or (B, T, S, 4, 4); None without
                the OFG.
            camera_mask: (B, S) bool, False for cameras left out of the fusion (camera dropout).
        Returns:
            (B, T, image_cond_dim) and, with the OFG, its output for the (B*T) flattened steps.
        """
        B, T, S = images.shape[:3]
        x = images.flatten(0, 2)  # B*T*S, 3, H, W
        if self.config.resize_shape is not None:
            x = resize_images(x, tuple(self.config.resize_shape))
        image_hw = tuple(x.shape[-2:])
        features = self.backbone(x)  # B*T*S, C, h, w
        if not self.config.use_ofg:
            return self.pool(features).view(B, T, -1), None
        features = features.unflatten(0, (B * T, S))  # B*T, S, C, h, w
        if pix_T_cam.ndim == 5:  # per frame: B, T, S, ... -> B*T, S, ...
            pix_T_cam, cam_T_world = pix_T_cam.flatten(0, 1), cam_T_world.flatten(0, 1)
        else:  # the same for every observation step: B, S, ... -> B*T, S, ...
            pix_T_cam, cam_T_world = (
                pix_T_cam.repeat_interleave(T, dim=0),
                cam_T_world.repeat_interleave(T, dim=0),
            )
        if camera_mask is not None:
            camera_mask = camera_mask.repeat_interleave(T, dim=0)
        out = self.ofg(features, pix_T_cam, cam_T_world, image_hw, camera_mask)
        return out.condition.view(B, T, -1), out

    def global_condition(
        self,
        images: Tensor,
        state: Tensor,
        pix_T_cam: Tensor | None,
        cam_T_world: Tensor | None,
        camera_mask: Tensor | None = None,
        env_state: Tensor | None = None,
    ) -> Tensor:
        """images (B, T, S, 3, H, W), state (B, T, Ds), env_state (B, T, De) or None -> (B, global_cond_dim).

        Per observation step: the image condition (the last step's only with ``fuse_last_step_only``), the
        state and the env state."""
        if env_state is not None:
            state = torch.cat([state, env_state.to(state.dtype)], dim=-1)  # B, T, Ds + De
        if self.config.fuse_last_step_only:  # B, T, ... -> B, 1, ...: the state keeps every step
            images = images[:, -1:]
            if pix_T_cam is not None and pix_T_cam.ndim == 5:
                pix_T_cam, cam_T_world = pix_T_cam[:, -1:], cam_T_world[:, -1:]
            image_cond, _ = self.encode_images(images, pix_T_cam, cam_T_world, camera_mask)
            return torch.cat([image_cond.flatten(1), state.flatten(1)], dim=-1)
        image_cond, _ = self.encode_images(images, pix_T_cam, cam_T_world, camera_mask)
        return torch.cat([image_cond, state], dim=-1).flatten(1)

    def generate_actions(self, global_cond: Tensor, noise: Tensor | None = None) -> Tensor:
        """Denoise a (B, horizon, Da) trajectory and keep ``n_action_steps`` from the current step."""
        B = global_cond.shape[0]
        sample = (
            noise
            if noise is not None
            else torch.randn(
                B,
                self.config.horizon,
                self.config.action_feature.shape[0],
                device=global_cond.device,
                dtype=global_cond.dtype,
            )
        )
        self.noise_scheduler.set_timesteps(self.num_inference_steps)
        for t in self.noise_scheduler.timesteps:
            timestep = torch.full((B,), t, dtype=torch.long, device=sample.device)
            model_output = self.unet(sample, timestep, global_cond=global_cond)
            sample = self.noise_scheduler.step(model_output, t, sample).prev_sample
        start = self.config.n_obs_steps - 1
        return sample[:, start : start + self.config.n_action_steps]

    def compute_loss(self, global_cond: Tensor, actions: Tensor, action_is_pad: Tensor | None) -> Tensor:
        """Epsilon (or sample) MSE of the diffusion head.

        Args:
            global_cond: (B, global_cond_dim).
            actions: (B, horizon, Da) normalised actions.
            action_is_pad: (B, horizon) or None: mask of copy-padded actions to leave out of the loss.
        """
        if actions.shape[1] != self.config.horizon:
            raise ValueError(
                f"`action`: expected horizon {self.config.horizon}, got shape {tuple(actions.shape)}"
            )
        eps = torch.randn_like(actions)
        timesteps = torch.randint(
            0, self.noise_scheduler.config.num_train_timesteps, (actions.shape[0],), device=actions.device
        )
        noisy = self.noise_scheduler.add_noise(actions, eps, timesteps)
        pred = self.unet(noisy, timesteps, global_cond=global_cond)
        target = eps if self.config.prediction_type == "epsilon" else actions
        loss = F.mse_loss(pred, target, reduction="none")
        if action_is_pad is None:
            return loss.mean()
        valid = (~action_is_pad).unsqueeze(-1).to(loss.dtype)
        return (loss * valid).sum() / (valid.sum() * loss.shape[-1]).clamp(min=1)
