"""Does a trained policy's image representation still locate the object outside the training square?

Neither OmniD nor DP succeeds in the position bands beyond the first (docs/results.md). This separates
the two halves of each policy: a linear probe (ridge regression) on the checkpoint's frozen image
condition (OmniD: its plane readout; DP: its cameras' spatial-softmax features; the state is left out)
is fitted to the grasp position (the gripper's x-y where the expert first closes it) on the training
episodes, its ridge weight is chosen on fresh in-distribution episodes, and it is then tested on expert
episodes of each position band. Where the probe's error stays near its in-distribution error, the
representation extrapolates and the policy's failure lies in its action head (the same UNet for both);
where it grows towards predicting the training mean, the representation itself stops at the square.

With ``--tables``, the same probe also reads expert episodes on unseen table textures. They come from the
same env seeds as the in-distribution validation set (the table changes only a texture, not the layout),
so each frame has a twin on the training table, and the script reports how far the table moves the
representation: the mean distance between twins relative to the spread of the validation frames
(:func:`table_shift`, in the training standardisation). A table that moves it by about its spread
scrambles the object's position as much as a new layout would.

    B=outputs/bench_mini_dp30 C=checkpoints/last/pretrained_model
    python -m lerobot_omnid.diagnostics.position_extrapolation --out outputs/position_extrapolation \\
        --train-root $B/data/select_apple_bcde \\
        --checkpoint omnid=$B/train/omnid/select_apple/$C \\
        --checkpoint diffusion=$B/train/diffusion/select_apple/$C [--tables ood1,ood2,ood3,ood4]

Records (once) 10 expert episodes per setting from env seed 400000, disjoint from every other seed set
of the benchmark (docs/benchmark.md#seeds), with the checkpoints' cameras and image size. Writes
``<out>/summary.json`` (the run summary every protocol writes; the probe's errors under ``results``) and
``<out>/report.md``; ``--report-only SUMMARY...`` rebuilds the report from such files alone (several runs'
side by side).
"""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path

import torch
from gym_omnid.constants import BACKGROUNDS, POSITION_BANDS
from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
from torch import Tensor

from lerobot_omnid.benchmark.commands import record_command, recorded_episodes
from lerobot_omnid.benchmark.plan import PROBE_MODULE as MODULE
from lerobot_omnid.benchmark.plan import PROBE_PROTOCOL as PROTOCOL
from lerobot_omnid.benchmark.plan import PROBE_SET as VALIDATION
from lerobot_omnid.benchmark.plan import TASK0
from lerobot_omnid.diagnostics import summary
from lerobot_omnid.diagnostics.checkpoints import expert_frames, load_policy
from lerobot_omnid.keys import IMAGE_KEY_PREFIX
from lerobot_omnid.measure.engine import code_commit, portable_command
from lerobot_omnid.measure.report import write_markdown
from lerobot_omnid.measure.results import RunSummary, read_run_summary

FRAMES = range(0, 17, 4)  # before the expert's grasp (frame 20 at the earliest): the object is unmoved
PROBE_SEED = 400_000  # first env seed of the probe's recordings
RIDGE_WEIGHTS = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0)  # per sample, on standardised features
BATCH = 32


def image_condition(policy, observation: dict[str, Tensor]) -> Tensor:
    """The image part of ``policy``'s condition for one preprocessed observation step: (B, D).

    OmniD: the plane readout of its cameras (``encode_images``); LeRobot's DP: its shared encoder's
    features of each camera, concatenated in the order of ``config.image_features``.
    """
    if policy.config.type == "omnid":
        images = torch.stack([observation[k] for k in policy.camera_keys], dim=1)[:, None]  # B, 1, S, 3, H, W
        pix_T_cam, cam_T_world = policy.camera_matrices(images.shape[0], tuple(images.shape[-2:]))
        condition, _ = policy.model.encode_images(images, pix_T_cam, cam_T_world)
        return condition[:, 0]
    if policy.config.type == "diffusion":
        if policy.config.use_separate_rgb_encoder_per_camera:
            raise ValueError("use_separate_rgb_encoder_per_camera: expected false, got true")
        images = torch.stack([observation[k] for k in policy.config.image_features], dim=1)  # B, N, 3, H, W
        features = policy.diffusion.rgb_encoder(images.flatten(0, 1))  # B*N, F
        return features.view(images.shape[0], -1)
    raise ValueError(f"policy type: expected omnid or diffusion, got {policy.config.type!r}")


def features_of(policy, preprocessor, items: list[dict[str, Tensor]]) -> Tensor:
    """(N, D) image conditions of dataset items, each through the checkpoint's own preprocessor."""
    keys = [k for k in policy.config.input_features if k.startswith(IMAGE_KEY_PREFIX)]
    keys.append("observation.state")
    out = []
    for i in range(0, len(items), BATCH):
        batch = items[i : i + BATCH]
        observation = {k: torch.stack([item[k] for item in batch]) for k in keys}
        observation["task"] = [item["task"] for item in batch]
        with torch.inference_mode():
            out.append(image_condition(policy, preprocessor(observation)))
    return torch.cat(out)


def fit_ridge(x: Tensor, y: Tensor, weight: float) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Ridge regression of y (N, K) on standardised x (N, D); ``weight`` per sample. Returns (mean, scale,
    coefficients (D, K), intercept (K,)), for :func:`predict`."""
    mean, scale = x.mean(dim=0), x.std(dim=0).clamp_min(1e-6)
    z = (x - mean) / scale
    gram = z.T @ z + weight * len(z) * torch.eye(z.shape[1], dtype=z.dtype)
    intercept = y.mean(dim=0)
    coefficients = torch.linalg.solve(gram, z.T @ (y - intercept))
    return mean, scale, coefficients, intercept


def predict(model: tuple[Tensor, Tensor, Tensor, Tensor], x: Tensor) -> Tensor:
    mean, scale, coefficients, intercept = model
    return (x - mean) / scale @ coefficients + intercept


def error_cm(predicted: Tensor, target: Tensor) -> float:
    return float((predicted - target).norm(dim=-1).mean() * 100.0)


def probe(
    train: tuple[Tensor, Tensor], validation: tuple[Tensor, Tensor], tests: dict[str, tuple[Tensor, Tensor]]
) -> dict:
    """Fit on ``train``, choose the ridge weight on ``validation``, report every set's mean error (cm)
    beside always predicting the training mean."""
    x, y = (t.double() for t in train)
    fits = {w: fit_ridge(x, y, w) for w in RIDGE_WEIGHTS}
    chosen = min(
        RIDGE_WEIGHTS, key=lambda w: error_cm(predict(fits[w], validation[0].double()), validation[1])
    )
    sets = {VALIDATION: validation, **tests}
    return {
        "ridge_weight": chosen,
        "train_cm": error_cm(predict(fits[chosen], x), y),
        "sets": {
            name: {
                "probe_cm": error_cm(predict(fits[chosen], fx.double()), fy.double()),
                "mean_cm": error_cm(y.mean(dim=0).expand_as(fy), fy.double()),
            }
            for name, (fx, fy) in sets.items()
        },
    }


def table_shift(train: Tensor, reference: Tensor, moved: Tensor) -> float:
    """How far a new table moves a representation: the mean distance between the twins of ``reference``
    and ``moved`` (N, D, the same frames on two tables), divided by the mean distance of ``reference``'s
    frames from their own mean, both in ``train``'s per-feature standardisation. 0: the table changes
    nothing; 1: as far as the object's position moves it."""
    mean, scale = train.double().mean(dim=0), train.double().std(dim=0).clamp_min(1e-6)
    z_reference, z_moved = ((t.double() - mean) / scale for t in (reference, moved))
    spread = (z_reference - z_reference.mean(dim=0)).norm(dim=-1).mean()
    return float((z_moved - z_reference).norm(dim=-1).mean() / spread)


def record(
    out: Path, layout: str, cameras: list[str], image_size: int, episodes: int, background: str = "id"
) -> Path:
    root = out / "data" / f"{TASK0}_{layout if background == 'id' else background}"
    if recorded_episodes(root) < episodes:
        cmd = record_command(TASK0, episodes, cameras, image_size, root, PROBE_SEED, layout, background)
        subprocess.run(cmd, check=True, capture_output=True)
    return root


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--train-root", type=Path, help="the checkpoints' training dataset")
    parser.add_argument(
        "--checkpoint", action="append", default=[], help="NAME=pretrained_model folder (repeatable)"
    )
    parser.add_argument("--episodes", type=int, default=10, help="expert episodes per probe setting")
    parser.add_argument(
        "--tables", default="", help="unseen table textures to probe too, comma-separated (e.g. ood1,ood2)"
    )
    parser.add_argument("--device", default="cpu")
    parser.add_argument(
        "--report-only",
        nargs="+",
        type=Path,
        metavar="SUMMARY",
        help="probe nothing: merge these summary.json files (committed summaries) into <out>/report.md",
    )
    args = parser.parse_args(argv)
    if args.report_only:
        merged: dict[str, dict] = {}
        for path in args.report_only:
            try:
                models = read_run_summary(path, PROTOCOL).results["models"]
            except ValueError as e:
                parser.error(f"--report-only: {e}")
            for name, result in models.items():
                if name in merged:
                    parser.error(f"--report-only: expected each model once, got {name!r} again in {path}")
                merged[name] = result
        write_markdown(probe_lines(merged), args.out / "report.md")
        return 0
    if args.train_root is None or not args.checkpoint:
        parser.error(
            "--train-root and --checkpoint: expected both (or --report-only), got "
            + ("neither" if args.train_root is None and not args.checkpoint else "only one")
        )
    tables = [t for t in args.tables.split(",") if t]
    for table in tables:
        if table not in BACKGROUNDS[1:]:
            parser.error(f"--tables: expected names from {BACKGROUNDS[1:]}, got {table!r}")
    checkpoints = {}
    for item in args.checkpoint:
        name, _, path = item.partition("=")
        if not path or not (Path(path) / "config.json").is_file():
            parser.error(f"--checkpoint: expected NAME=<folder with config.json>, got {item!r}")
        checkpoints[name] = Path(path)

    meta = LeRobotDatasetMetadata(f"local/{args.train_root.name}", root=args.train_root)
    image_keys = [k for k in meta.features if k.startswith(IMAGE_KEY_PREFIX)]
    cameras = [k.removeprefix(IMAGE_KEY_PREFIX) for k in image_keys]
    image_size = meta.features[image_keys[0]]["shape"][0]
    roots = {"train": args.train_root, VALIDATION: record(args.out, "id", cameras, image_size, args.episodes)}
    roots |= {band: record(args.out, band, cameras, image_size, args.episodes) for band in POSITION_BANDS}
    roots |= {t: record(args.out, "id", cameras, image_size, args.episodes, background=t) for t in tables}
    frames = {name: expert_frames(root, FRAMES) for name, root in roots.items()}

    results = {}
    for name, checkpoint in checkpoints.items():
        policy, preprocessor, _ = load_policy(checkpoint, meta, args.device)
        sets = {k: (features_of(policy, preprocessor, items), grasp) for k, (items, grasp) in frames.items()}
        validation, train = sets.pop(VALIDATION), sets.pop("train")
        found = probe(train, validation, sets)
        results[name] = {"checkpoint": portable_command([str(checkpoint)])[0], **found}
        for t in tables:
            results[name]["sets"][t]["table_shift"] = table_shift(train[0], validation[0], sets[t][0])
    settings = {"probe_seed": PROBE_SEED, "episodes": args.episodes, "tables": tables}
    summary.finish(args, PROTOCOL, MODULE, argv, settings, {"models": results}, code_commit(), report_lines)
    return 0


def report_lines(found: RunSummary) -> list[str]:
    return probe_lines(found.results["models"])


def probe_lines(results: dict[str, dict]) -> list[str]:
    """The probe's tables (error per set and model; with tables, each table's shift) from the models' probe
    results of one run summary or several merged."""
    names = list(results)
    lines = ["| set | " + " | ".join(f"{n} probe (cm)" for n in names) + " | training mean (cm) |"]
    lines.append("| --- |" + " --- |" * (len(names) + 1))
    for s in results[names[0]]["sets"]:
        row = [f"{results[n]['sets'][s]['probe_cm']:.2f}" if s in results[n]["sets"] else "-" for n in names]
        lines.append(f"| {s} | " + " | ".join(row) + f" | {results[names[0]]['sets'][s]['mean_cm']:.2f} |")
    tables = [s for s in results[names[0]]["sets"] if "table_shift" in results[names[0]]["sets"][s]]
    if tables:
        lines += ["", "| table | " + " | ".join(f"{n} table shift" for n in names) + " |"]
        lines.append("| --- |" + " --- |" * len(names))
        for t in tables:
            shifts = [f"{results[n]['sets'][t].get('table_shift', float('nan')):.2f}" for n in names]
            lines.append(f"| {t} | " + " | ".join(shifts) + " |")
    return lines


if __name__ == "__main__":
    raise SystemExit(main())
