"""Copy a LeRobot checkpoint with other cameras as its image inputs, to fine-tune it on a new view.

``lerobot-train --policy.path=<checkpoint>`` keeps the checkpoint's ``input_features``, and a
``--policy.input_features=...`` override is merged into them rather than replacing them, so a stock policy
trained on cameras B-E would still ask for B-E when fine-tuned on a camera-A dataset. This writes a copy of
the checkpoint whose ``config.json`` lists the state and the new cameras' images instead (same image shape
as the old ones); processors are copied unchanged. Weights are copied unchanged where they do not depend on
the number of cameras (LeRobot's ACT, and VQ-BeT with its one image). LeRobot's Diffusion Policy with one
shared image encoder conditions its UNet on every camera's features side by side; a copy with one camera
gets, in each FiLM layer, the sum of the old cameras' columns (:func:`fold_camera_columns`), so that it
behaves exactly as the old checkpoint given the new camera's image in every slot. OmniD needs none of this:
``--policy.cameras`` selects its cameras.

    python -m lerobot_omnid.benchmark.checkpoint_cameras \
        --src <pretrained_model> --dst <folder> --cameras cam_a
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import torch
from safetensors import safe_open
from safetensors.torch import save_file

from lerobot_omnid.keys import IMAGE_KEY_PREFIX, image_key

CONFIG = "config.json"
WEIGHTS = "model.safetensors"
FILM_WEIGHT = ".cond_encoder.1.weight"
"""Suffix of the Linear weight of each FiLM layer of LeRobot's DP UNet (``cond_encoder = Mish, Linear``)."""


def fold_camera_columns(
    weight: torch.Tensor, step_embed_dim: int, n_obs_steps: int, before: int, after: int, n_cameras: int
) -> torch.Tensor:
    """A FiLM weight for one camera from one for ``n_cameras`` cameras sharing an image encoder.

    LeRobot's DP conditions on ``[step embedding (E), then per observation step: state (before), the
    cameras' features (n_cameras x F), environment state (after)]``, passed through an element-wise Mish
    before the Linear layer. Summing a step's ``n_cameras`` column blocks gives a layer whose output on one
    camera's features equals the old layer's on that camera's features repeated in every slot.

    Args:
        weight: (C, E + n_obs_steps * (before + n_cameras * F + after)).
    Returns:
        (C, E + n_obs_steps * (before + F + after)).
    """
    per_step, rest = divmod(weight.shape[1] - step_embed_dim, n_obs_steps)
    feature_dim, rest_f = divmod(per_step - before - after, n_cameras)
    if rest or rest_f or feature_dim <= 0:
        raise ValueError(
            f"FiLM weight: expected {step_embed_dim} + {n_obs_steps} x ({before} + {n_cameras} x F + "
            f"{after}) columns, got {weight.shape[1]}"
        )
    blocks = [weight[:, :step_embed_dim]]
    for step in range(n_obs_steps):
        start = step_embed_dim + step * per_step
        cams = weight[:, start + before : start + before + n_cameras * feature_dim]
        blocks += [
            weight[:, start : start + before],
            cams.reshape(weight.shape[0], n_cameras, feature_dim).sum(dim=1),
            weight[:, start + per_step - after : start + per_step],
        ]
    return torch.cat(blocks, dim=1)


def fold_diffusion_weights(config: dict, weights: dict[str, torch.Tensor], n_cameras: int) -> None:
    """Fold every FiLM weight of a DP checkpoint (``config``, ``weights``, in place) to one camera."""
    if config.get("use_separate_rgb_encoder_per_camera"):
        raise ValueError(
            "use_separate_rgb_encoder_per_camera: expected false (one encoder shared by the cameras, which "
            "the new camera can use), got true"
        )
    dims = {kind: 0 for kind in ("STATE", "ENV")}
    for ft in config["input_features"].values():
        if ft["type"] in dims:
            dims[ft["type"]] += ft["shape"][0]
    films = [key for key in weights if key.endswith(FILM_WEIGHT)]
    if not films:
        raise ValueError(f"{WEIGHTS}: expected the UNet's FiLM weights (*{FILM_WEIGHT}), found none")
    for key in films:
        weights[key] = fold_camera_columns(
            weights[key],
            config["diffusion_step_embed_dim"],
            config["n_obs_steps"],
            before=dims["STATE"],
            after=dims["ENV"],
            n_cameras=n_cameras,
        ).contiguous()


def retarget_cameras(src: Path, dst: Path, cameras: list[str]) -> Path:
    """Write the copy at ``dst`` (replacing it); returns ``dst``. The new config is written last, so a
    ``dst`` with a ``config.json`` is complete."""
    config = json.loads((src / CONFIG).read_text())
    features = config.get("input_features") or {}
    images = [ft for key, ft in features.items() if key.startswith(IMAGE_KEY_PREFIX)]
    if not images:
        raise ValueError(
            f"{src / CONFIG}: input_features has no {IMAGE_KEY_PREFIX}* entry to take the shape from"
        )
    if not cameras or len(set(cameras)) != len(cameras):
        raise ValueError(f"cameras: expected distinct camera names, got {cameras}")
    weights, metadata = None, None
    if config.get("type") == "diffusion" and len(cameras) != len(images):
        if len(cameras) != 1:
            raise ValueError(
                f"cameras: a diffusion checkpoint with {len(images)} cameras can be copied with its own "
                f"number of cameras or with one, got {len(cameras)}"
            )
        with safe_open(src / WEIGHTS, "pt") as f:  # one read: the tensors and the file's metadata
            weights, metadata = {k: f.get_tensor(k) for k in f.keys()}, f.metadata()  # noqa: SIM118 (not iterable)
        fold_diffusion_weights(config, weights, len(images))
    others = {key: ft for key, ft in features.items() if not key.startswith(IMAGE_KEY_PREFIX)}
    config["input_features"] = {**others, **{image_key(cam): dict(images[0]) for cam in cameras}}
    if dst.exists():
        shutil.rmtree(dst)
    skip = (CONFIG, WEIGHTS) if weights is not None else (CONFIG,)
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns(*skip))
    if weights is not None:
        save_file(weights, dst / WEIGHTS, metadata)
    (dst / CONFIG).write_text(json.dumps(config, indent=4) + "\n")
    return dst


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--src", type=Path, required=True, help="a checkpoint's pretrained_model folder")
    parser.add_argument("--dst", type=Path, required=True, help="folder of the copy (replaced)")
    parser.add_argument("--cameras", required=True, help="comma-separated cameras, e.g. cam_a")
    args = parser.parse_args(argv)
    if not (args.src / CONFIG).is_file():
        parser.error(f"--src: expected a checkpoint folder with {CONFIG}, got {args.src}")
    try:
        retarget_cameras(args.src, args.dst, [c.strip() for c in args.cameras.split(",") if c.strip()])
    except ValueError as e:
        parser.error(str(e))
    print(f"{args.dst}: inputs {', '.join(json.loads((args.dst / CONFIG).read_text())['input_features'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
