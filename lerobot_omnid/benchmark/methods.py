"""What each method is trained, fine-tuned and controlled with: every ``lerobot-train`` / ``lerobot-eval``
option that differs from the policy's LeRobot default, each with the reason it is set.

Pure data and small functions of a profile's sizes (``lerobot_omnid.benchmark.plan.BenchmarkProfile``); the
plans (``omnid-benchmark``, the main job, rigs and wrist, readout selection, robustness) take their options
from here, so one method is trained alike by all of them.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from gym_omnid import TRAIN_CAMERAS
from gym_omnid.constants import STATE_DIM

from lerobot_omnid.benchmark.commands import SIM_VOLUME_BOUNDS, json_list

if TYPE_CHECKING:
    from lerobot_omnid.benchmark.plan import BenchmarkProfile

METHODS = ("omnid", "diffusion", "act", "vqbet")
"""LeRobot policy types, in the order of the paper's tables."""
CONTROLS = ("blind", "scrambled", "perturbed")
"""Evaluations of a trained checkpoint that test what drives it (see :func:`control_flags`)."""
PERTURBED_LEVEL = 2.0
"""cm and degrees by which the ``perturbed`` control moves and turns every camera (a carelessly measured
rig; ``omnid-robustness`` measures the whole curve, and this is its first draw at this level)."""
CONTROL_LABELS = {
    "blind": "blind",
    "scrambled": "scrambled geometry",
    "perturbed": f"calibration off by {PERTURBED_LEVEL:g} cm and {PERTURBED_LEVEL:g} deg",
}
ABLATIONS = ("omnid_resnet101", "omnid_no_ofg", "omnid_cam_a")
CAMERA_A = ("cam_a",)
VQBET_CAMERA = ("cam_b",)  # LeRobot's VQ-BeT takes exactly one image

Flag = tuple[str, str]
"""A command-line option and why it is set."""


@dataclass(frozen=True)
class Variant:
    """A method trained with other options on task 0 and evaluated like it, under its own table row: an
    option chosen on validation (:func:`variant_flags`)."""

    name: str  # its table row, e.g. "omnid_clip2"
    method: str
    label: str  # e.g. "OmniD clip 2"
    flags: tuple[Flag, ...]  # replace the method's option of the same name, or add to them


def with_options(base: Sequence[Flag], changes: Sequence[Flag]) -> list[Flag]:
    """``base`` with each option of ``changes`` replacing the one of the same name (``--policy.x=``), the
    new ones appended."""
    names = {flag.split("=", 1)[0] for flag, _ in changes}
    return [item for item in base if item[0].split("=", 1)[0] not in names] + list(changes)


def input_features(cameras: Sequence[str], image_size: int, state_dim: int = STATE_DIM) -> str:
    """``--policy.input_features`` JSON: the state and the images of ``cameras`` (the policy's inputs)."""
    features = {"observation.state": {"type": "STATE", "shape": [state_dim]}}
    for cam in cameras:
        features[f"observation.images.{cam}"] = {"type": "VISUAL", "shape": [3, image_size, image_size]}
    return json.dumps(features, separators=(",", ":"))


NO_DOWNLOAD = "offline: no pretrained torchvision weights (nothing is downloaded); all methods start from a "
NO_DOWNLOAD += "randomly initialised ResNet, as OmniD does"
GROUP_NORM = "GroupNorm instead of BatchNorm for a backbone trained from scratch on small batches of "
GROUP_NORM += "correlated frames, as OmniD and the Diffusion Policy paper do"
NO_CROP = (
    "no crop: OmniD never crops (it would invalidate the intrinsics), so every method sees the same pixels"
)


def diffusion_head_flags(p: BenchmarkProfile) -> list[Flag]:
    """Options of LeRobot's conditional UNet and its schedule, the same for OmniD and DP."""
    if not p.small:
        return []  # the defaults are the paper's: UNet (512,1024,2048), DDPM 100 steps, lr 1e-4, 500 warm-up
    same = "; the same for OmniD and DP"
    return [
        (
            "--policy.down_dims=[128,256,512]",
            "a UNet with 1/16 of the default's weights, for 2 CPU cores" + same,
        ),
        (
            "--policy.noise_scheduler_type=DDIM",
            "sampling in 10 DDIM steps instead of 100 DDPM steps: 10x "
            "cheaper evaluation, same training objective" + same,
        ),
        ("--policy.num_inference_steps=10", "see DDIM"),
        (
            "--policy.prediction_type=sample",
            "short run: the head regresses the clean action chunk instead of the noise. Measured: DP "
            "fitting one expert episode in 400 steps reached 0.8 cm open-loop error with sample, 17 cm "
            "with epsilon (holding the pose: 2 cm); epsilon needs far more steps than a CPU run has" + same,
        ),
        ("--policy.optimizer_lr=3e-4", "short run: 3x the default learning rate" + same),
        ("--policy.scheduler_warmup_steps=50", "short run: 50 warm-up steps instead of 500" + same),
    ]


def method_flags(method: str, p: BenchmarkProfile) -> list[Flag]:
    """Options of ``method`` trained from scratch on the B-E set, beyond type, device and push_to_hub."""
    if method == "omnid":
        shape = "[16,20,8]" if p.small else "[32,40,16]"
        side = p.image_size // 16
        flags = [
            ("--policy.cameras=" + json_list(TRAIN_CAMERAS), "cameras B-E, the protocol's training views"),
            (
                f"--policy.volume_bounds={SIM_VOLUME_BOUNDS}",
                "the benchmark's workspace (objects lie in x "
                "0.3-0.8 m, y -0.3-0.35 m) instead of the paper robot's",
            ),
            (
                f"--policy.volume_shape={shape}",
                "4 cm cells, CPU size"
                if p.small
                else "2 cm cells over the benchmark's smaller workspace (paper: 64x16x64 over its own)",
            ),
            ("--policy.backbone_layer=3", f"stride-16 features ({side}x{side} maps at {p.image_size} px)"),
        ]
        if p.small:
            flags += [
                ("--policy.d_model=64", "CPU size: OFG width 64 (paper 128)"),
                ("--policy.num_layers=2", "CPU size: 2 OFG layers (paper 6)"),
                ("--policy.checkpoint_sampling=false", "memory is no concern at this size: no recomputation"),
                (
                    "--policy.plane_readout=keypoints",
                    "short run: the plane is read out as 16 soft-argmax keypoints in the base frame instead "
                    "of flattened (the paper's), selected on validation seeds among five readouts "
                    "(lerobot_omnid/benchmark/readout_selection.py; numbers in docs/results.md)",
                ),
                ("--policy.compressed_channels=16", "see plane_readout: 16 keypoints"),
            ]
        if p.fuse_last_step_only:
            flags.append(
                (
                    "--policy.fuse_last_step_only=true",
                    "backbone and OFG on the last observation step only, as the authors' code (the state "
                    "keeps both): cheaper steps, supported by the validation protocol (docs/benchmark.md)",
                )
            )
        return flags + diffusion_head_flags(p)
    if method == "diffusion":
        return [
            ("--policy.pretrained_backbone_weights=null", NO_DOWNLOAD),
            ("--policy.use_group_norm=true", GROUP_NORM),
            ("--policy.crop_shape=null", NO_CROP),
            (
                "--policy.use_separate_rgb_encoder_per_camera=false",
                "one ResNet-18 shared by the cameras, as in "
                "OmniD (one per camera: 4x the backbone weights and compute)",
            ),
            (
                "--policy.horizon=16",
                "OmniD's (the paper's) action timing: 2 observations, 16 predicted "
                "actions, 8 executed (LeRobot's DP default: 64 predicted, 32 executed)",
            ),
            ("--policy.n_action_steps=8", "see horizon"),
            ("--policy.drop_n_last_frames=7", "horizon - n_action_steps - n_obs_steps + 1, as OmniD"),
            *diffusion_head_flags(p),
        ]
    if method == "act":
        return [
            ("--policy.pretrained_backbone_weights=null", NO_DOWNLOAD),
            (
                "--policy.chunk_size=16",
                "the same 16 predicted actions as OmniD/DP (default 100: 10 s at "
                "10 Hz, longer than an expert episode)",
            ),
            ("--policy.n_action_steps=8", "8 actions executed per prediction, as OmniD/DP"),
        ]
    if method == "vqbet":
        flags = [
            ("--policy.pretrained_backbone_weights=null", NO_DOWNLOAD),
            ("--policy.use_group_norm=true", GROUP_NORM),
            ("--policy.crop_shape=null", NO_CROP + " (VQ-BeT's default: random 84x84 crops)"),
            (
                "--policy.input_features=" + input_features(VQBET_CAMERA, p.image_size),
                "LeRobot's VQ-BeT takes exactly one image: camera B (the front view) of the four",
            ),
            ("--policy.n_obs_steps=2", "2 observations, as OmniD/DP (default 5)"),
            ("--policy.action_chunk_size=8", "8 actions executed per prediction, as OmniD/DP (default 5)"),
            (
                f"--policy.n_vqvae_training_steps={max(p.steps // 5, 1)}",
                "the action tokeniser (VQ-VAE) "
                "trains in the first 20% of the steps, the GPT after it (default 20000 = 20% of 100k)",
            ),
        ]
        if p.small:
            flags.append(("--policy.scheduler_warmup_steps=50", "short run: 50 warm-up steps, as OmniD/DP"))
        return flags
    raise ValueError(f"method: expected one of {list(METHODS)}, got {method!r}")


def finetune_flags(method: str) -> list[Flag]:
    """Options that turn a B-E checkpoint (given with ``--policy.path``) into a camera-A policy."""
    if method == "omnid":
        why = "camera A only: its calibration comes from the dataset, every weight from the checkpoint"
        return [("--policy.cameras=" + json_list(CAMERA_A), why)]
    if method in ("diffusion", "act", "vqbet"):
        why = (
            "a copy of the task-0 checkpoint whose image input is camera A instead of the training "
            "camera(s) (lerobot_omnid.benchmark.checkpoint_cameras: a --policy.input_features override "
            "is merged with the checkpoint's, it cannot drop them); "
        )
        why += (
            "DP conditions on each camera's features side by side: the copy's FiLM layers get the sum of "
            "the four cameras' weights, so it starts as the B-E model given camera A's image in every slot"
            if method == "diffusion"
            else "the weights do not depend on the camera"
        )
        flags = [("--policy.path=<copy with camera A>", why)]
        if method == "vqbet":
            why = "the checkpoint's action tokeniser is kept; the GPT gets the usual warm-up and schedule"
            flags.append(("--policy.n_vqvae_training_steps=0", why))
        return flags
    raise ValueError(f"method: expected one of {list(METHODS)}, got {method!r}")


WIDE_CLIP: Flag = (
    "--policy.clip_sample_range=2.0",
    "the head's clean-sample clip at twice the training actions' range: at 1.0 (the default) it cannot "
    "command a TCP target outside the training actions' range, which most position-band layouts need "
    "(python -m lerobot_omnid.diagnostics.action_reach)",
)
POSITION_VARIANTS = (
    Variant("omnid_clip2", "omnid", "OmniD clip 2", (WIDE_CLIP,)),
    *(
        Variant(
            f"omnid_clip2_shift{cm}",
            "omnid",
            f"OmniD clip 2, shift {cm} cm",
            (
                WIDE_CLIP,
                (
                    f"--policy.position_shift_m={cm / 100:g}",
                    f"the whole scene shifted by up to {cm} cm in x and y per training sample (cameras, "
                    "state and action together): the head sees objects and targets beyond the square",
                ),
            ),
        )
        for cm in (5, 10)
    ),
    Variant("diffusion_clip2", "diffusion", "DP clip 2", (WIDE_CLIP,)),
)
"""The position validation's candidates beside OmniD and DP as trained
(docs/benchmark.md#position-its-protocol)."""


SINGLE_CAMERA = Variant(
    "omnid_single_camera",
    "omnid",
    "OmniD single-camera pre-training",
    (
        (
            "--policy.single_camera_rate=0.5",
            "half of the training samples fused from one random camera: the OFG learns to lift the scene "
            "from a single view, as it must from a new camera",
        ),
    ),
)
"""OmniD pre-trained to lift from one view: a start of the new-camera recipes."""


@dataclass(frozen=True)
class FewshotRecipe:
    """How a B-E model of task 0 is fine-tuned on the camera-A episodes. The profile's own recipe (the
    paper's: ``finetune_steps`` at the training learning rate, every weight trained, from the method as
    trained) has the name ""; any other is chosen on validation (``lerobot_omnid.benchmark.new_camera``)
    and its models are table rows of their own, ``<method>_<name>``."""

    name: str
    label: str  # e.g. "1000 steps"
    steps: int | None = None  # None: the profile's finetune_steps; 0: zero-shot, on task 0 only
    lr: float | None = None  # None: the method's training learning rate
    frozen: tuple[str, ...] = ()  # OmniD only: --policy.frozen_modules
    replay: bool = False  # OmniD only: the camera-A episodes merged with as many replayed B-E ones
    start: str = ""  # OmniD only: the variant it starts from ("": the method as trained)

    def for_method(self, method: str) -> FewshotRecipe:
        """The recipe as ``method`` follows it: OmniD all of it; the others its steps and learning rate
        (LeRobot's policies have no option to freeze parts, and take their cameras side by side, so they
        cannot leave a camera out per sample as replay needs)."""
        if method == "omnid":
            return self
        return FewshotRecipe(self.name, self.label, self.steps, self.lr)


PAPER_RECIPE = FewshotRecipe("", "the paper's fine-tuning")


def fewshot_model(method: str, recipe: FewshotRecipe) -> str:
    """The table row of ``method`` fine-tuned by ``recipe``: the method's own for the profile's recipe."""
    return f"{method}_{recipe.name}" if recipe.name else method


def recipe_flags(method: str, recipe: FewshotRecipe) -> list[Flag]:
    """Options of ``method``'s fine-tuning by ``recipe`` (its ``for_method`` form), beyond the path of the
    checkpoint it starts from."""
    changes: list[Flag] = []
    if recipe.replay:
        cameras = json_list((*CAMERA_A, *TRAIN_CAMERAS))
        why = "cameras A-E: each replayed frame shows the policy B-E, each camera-A frame camera A alone"
        changes.append((f"--policy.cameras={cameras}", why))
    if recipe.lr is not None:
        changes.append((f"--policy.optimizer_lr={recipe.lr:g}", "the recipe's fine-tuning learning rate"))
    if recipe.frozen:
        why = "the recipe's parts kept from the B-E model"
        changes.append(("--policy.frozen_modules=" + json_list(recipe.frozen), why))
    base = [(f, why) for f, why in finetune_flags(method) if not f.startswith("--policy.path=")]
    return with_options(base, changes)


RIG_VARIANTS = (
    *(
        Variant(
            f"omnid_rot{deg}",
            "omnid",
            f"OmniD cameras turned up to {deg} deg",
            (
                (
                    f"--policy.camera_rotation_deg={deg}",
                    f"each training sample's cameras turned about their centres by up to {deg} degrees, "
                    "images warped and extrinsics turned with them: poses the training rig never had",
                ),
            ),
        )
        for deg in (5, 10)
    ),
    SINGLE_CAMERA,
)
"""The moved-rig validation's candidates beside OmniD as trained
(docs/benchmark.md#moved-rigs-its-protocol)."""


def variant_flags(variant: Variant, p: BenchmarkProfile) -> list[Flag]:
    """Options of ``variant``: its method's, with its own options replacing or added to them."""
    return with_options(method_flags(variant.method, p), variant.flags)


def ablation_flags(name: str, p: BenchmarkProfile) -> list[Flag]:
    base = method_flags("omnid", p)
    if name == "omnid_resnet101":
        return [*base, ("--policy.vision_backbone=resnet101", "ablation: deeper backbone")]
    if name == "omnid_no_ofg":
        return [*base, ("--policy.use_ofg=false", "ablation: per-camera keypoint features, no OFG")]
    if name == "omnid_cam_a":
        return [(f, r) for f, r in base if not f.startswith("--policy.cameras=")] + [
            (
                "--policy.cameras=" + json_list(CAMERA_A),
                f"ablation: one view, camera A ({p.episodes} episodes)",
            )
        ]
    raise ValueError(f"ablation: expected one of {list(ABLATIONS)}, got {name!r}")


def method_controls(method: str) -> tuple[str, ...]:
    """The controls of ``method``: every method's blind one, and OmniD's scrambled and perturbed geometry."""
    return CONTROLS if method == "omnid" else ("blind",)


def control_flags(
    method: str, control: str, cameras: Sequence[str], calibration_file: Path | str
) -> list[Flag]:
    """Options that turn an evaluation of ``method``'s checkpoint into its ``control``: only the state can
    drive it (blind), or its images are lifted with the wrong geometry (scrambled) or a slightly wrong one
    (perturbed; both OmniD only)."""
    if control not in method_controls(method):
        raise ValueError(
            f"control of {method}: expected one of {list(method_controls(method))}, got {control!r}"
        )
    if method == "omnid":
        why = {
            "blind": "every camera turned away from the volume in its calibration (lerobot_omnid."
            "benchmark.control_calibration): no anchor is visible, the images contribute nothing",
            "scrambled": "the cameras' calibrations permuted (each gets the next camera's, none keeps "
            "its own): real images lifted into the volume with the wrong geometry",
            "perturbed": f"every camera moved by {PERTURBED_LEVEL:g} cm and turned by {PERTURBED_LEVEL:g} "
            "degrees in its calibration (random directions, fixed seed): how much a measured rig's error "
            "costs",
        }[control]
        return [(f"--policy.calibration_path={calibration_file}", why)]
    why = "black images (every pixel zero) from every camera: only the state can drive the policy"
    return [(f"--env.blackout_cameras=[{','.join(cameras)}]", why)]
