"""Which calibration errors hurt, and why: where each ``omnid-robustness`` draw moves the object in the plane.

A BEV policy reads the gripper from the state and the object from its plane. With a camera's calibration
off, the plane samples, for a point of the table, the pixel where that camera really shows another point
(:func:`lerobot_omnid.geometry.point_seen_on_plane`): the object appears displaced by ``point - seen`` in
that camera's contribution. Per draw of ``omnid-robustness``'s calibration perturbation (same seeds, same
draws: :func:`lerobot_omnid.benchmark.robustness_plan.camera_offsets`), this gives each camera's
displacement of the object's nominal position, their mean (where the fused plane would put the object when
the cameras agree) and their spread (how much they disagree, which blurs it instead). Beside a robustness
summary it lists each draw's success, so that a draw that fails can be matched with its displacement and
with the grasp's tolerance: the report relates each draw's success to its mean displacement (Spearman's
rank correlation per level, and the draws within the tolerance against those beyond it) and draws it,
``<out>/calibration_shift.png``. Pure geometry: no episode is run.

    python -m lerobot_omnid.diagnostics.calibration_shift --out outputs/calibration_shift \\
        --checkpoint outputs/six_tasks/train/omnid/select_apple/checkpoints/last/pretrained_model \\
        --levels 2 --draws 10 [--robustness-summary outputs/robustness/summary.json --label omnid]

Writes ``<out>/summary.json`` and ``<out>/report.md``; ``--report-only SUMMARY...`` rebuilds the report
from such files alone.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch
from gym_omnid.constants import GRIPPER_MAX_GAP
from gym_omnid.tasks.select_apple import APPLE_RADIUS

from lerobot_omnid.benchmark.robustness_plan import (
    camera_offsets,
    checkpoint_from_config,
    perturbed_calibrations,
)
from lerobot_omnid.cli import csv_of, positive_int
from lerobot_omnid.diagnostics import summary
from lerobot_omnid.geometry import point_seen_on_plane
from lerobot_omnid.measure.charts import pyplot, save_figure
from lerobot_omnid.measure.engine import code_commit
from lerobot_omnid.measure.results import RunSummary, read_run_summary
from lerobot_omnid.measure.stats import fisher_exact, spearman

PROTOCOL = "calibration_shift"
MODULE = "lerobot_omnid.diagnostics.calibration_shift"
APPLE = (0.55, 0.12, 0.035)  # select_apple's apple: the centre of its training square, its centre's height
GRASP_TOLERANCE_CM = 100 * (GRIPPER_MAX_GAP / 2 - APPLE_RADIUS)
"""How far the open pads may be off the apple's centre along their closing axis and still close around it."""
CHART = "calibration_shift.png"


def displacements(true: dict, believed: dict, point: torch.Tensor) -> dict[str, list[float]]:
    """Per camera, the x-y displacement (cm) of an object at ``point`` in that camera's contribution to the
    plane: ``point`` minus where the camera really looks when the policy samples ``point``."""
    out = {}
    for cam, calibration in true.items():
        K = torch.tensor(calibration.K, dtype=torch.float64)
        seen = point_seen_on_plane(
            K,
            torch.tensor(believed[cam].T_cam_world, dtype=torch.float64),
            torch.tensor(calibration.T_cam_world, dtype=torch.float64),
            point,
        )
        out[cam] = (100 * (point - seen)[:2]).tolist()
    return out


def draw_row(per_camera: dict[str, list[float]]) -> dict:
    """The cameras' displacements (cm), their mean vector's length and their spread about it."""
    vectors = torch.tensor(list(per_camera.values()), dtype=torch.float64)  # cameras, 2
    mean = vectors.mean(dim=0)
    return {
        "cameras_cm": {cam: float(torch.tensor(v).norm()) for cam, v in per_camera.items()},
        "mean_cm": float(mean.norm()),
        "mean_vector_cm": mean.tolist(),
        "spread_cm": float((vectors - mean).norm(dim=-1).mean()),
    }


def draw_successes(
    path: Path, label: str, perturbation_seed: int
) -> dict[tuple[float, int], tuple[int, int]]:
    """{(level, draw): (successes, episodes)} of ``label``'s calibration rows in a robustness summary made
    with the same ``perturbation_seed`` (else its draws are others); errors name the field."""
    run = read_run_summary(path, "omnid-robustness")
    seed = run.settings.get("perturbation_seed")
    if seed != perturbation_seed:
        raise ValueError(f"{path}: perturbation_seed: expected {perturbation_seed}, got {seed}")
    checkpoints = run.results["checkpoints"]
    if label not in checkpoints:
        raise ValueError(f"{path}: --label: expected one of {sorted(checkpoints)}, got {label!r}")
    found = {}
    for row in checkpoints[label]["rows"]:
        if row["condition"] == "calibration":
            for name, successes, episodes in row["parts"]:
                found[(row["level"], int(name.removeprefix("draw ")))] = (successes, episodes)
    return found


def relation_lines(draws: list[dict]) -> list[str]:
    """Per level with successes and all levels together: Spearman's rho between a draw's success rate and
    its mean displacement, and the draws within ``GRASP_TOLERANCE_CM`` pooled against those beyond it
    (Fisher p). A negative rho and fewer successes beyond the tolerance say the agreed misplacement is what
    fails the grasp."""
    measured = [d for d in draws if "successes" in d]
    groups = [
        (f"{lv:g} cm, {lv:g} deg", [d for d in measured if d["level"] == lv])
        for lv in dict.fromkeys(d["level"] for d in measured)
    ]
    if len(groups) > 1:
        groups.append(("all levels", measured))
    lines = []
    for name, group in groups:
        if len(group) < 2:
            continue
        rho = spearman([d["mean_cm"] for d in group], [d["successes"] / d["episodes"] for d in group])
        within = [d for d in group if d["mean_cm"] <= GRASP_TOLERANCE_CM]
        beyond = [d for d in group if d["mean_cm"] > GRASP_TOLERANCE_CM]
        counts = [(sum(d["successes"] for d in g), sum(d["episodes"] for d in g)) for g in (within, beyond)]
        split = (
            f"{len(within)} draws within {GRASP_TOLERANCE_CM:.1f} cm {counts[0][0]}/{counts[0][1]}, "
            f"{len(beyond)} beyond {counts[1][0]}/{counts[1][1]}"
        )
        if within and beyond:
            split += f" (Fisher p = {fisher_exact(*counts[0], *counts[1]):.2g})"
        rho_text = "n/a (constant)" if rho != rho else f"{rho:+.2f}"
        lines.append(f"- {name}: Spearman rho (success, mean displacement) = {rho_text}; {split}")
    if not lines:
        return []
    return [
        "",
        f"Success against the mean displacement (grasp tolerance: the open pads' half-gap less the apple's "
        f"radius, {GRASP_TOLERANCE_CM:.1f} cm):",
        "",
        *lines,
    ]


def shift_chart(draws: list[dict], path: Path) -> Path:
    """Each draw's success (%) against its mean displacement (cm), a colour per level, the grasp tolerance
    as a vertical line."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for i, level in enumerate(dict.fromkeys(d["level"] for d in draws)):
        points = [d for d in draws if d["level"] == level]
        ax.scatter(
            [d["mean_cm"] for d in points],
            [100 * d["successes"] / d["episodes"] for d in points],
            color=f"C{i}",
            label=f"{level:g} cm, {level:g} deg",
        )
    ax.axvline(GRASP_TOLERANCE_CM, color="gray", ls="--", lw=1, label="grasp tolerance")
    ax.set(
        title="Each calibration draw: success against where the plane puts the object",
        xlabel="mean displacement of the object over the cameras (cm)",
        ylabel="success (%)",
        ylim=(-4, 104),
    )
    ax.legend(fontsize="small")
    return save_figure(fig, path)


def report_lines(run: RunSummary) -> list[str]:
    s = run.settings
    cameras = list(run.results["draws"][0]["cameras_cm"])
    lines = [
        f"# Where each calibration draw moves the object: {s['checkpoint']} ({run.commit})",
        "",
        f"Object at {s['point']} m; per draw, each camera's displacement of it in the plane (cm), their mean "
        "(where agreeing cameras put it) and their spread (disagreement: blur); success from the robustness "
        "run where given.",
        "",
        "| level | draw | " + " | ".join(cameras) + " | mean (cm) | spread (cm) | success |",
        "|---|---|" + "---|" * (len(cameras) + 3),
    ]
    for r in run.results["draws"]:
        per_camera = " | ".join(f"{r['cameras_cm'][c]:.1f}" for c in cameras)
        success = f"{r['successes']}/{r['episodes']}" if "successes" in r else "-"
        lines.append(
            f"| {r['level']:g} | {r['draw']} | {per_camera} | {r['mean_cm']:.1f} | {r['spread_cm']:.1f} | "
            f"{success} |"
        )
    return [*lines, *relation_lines(run.results["draws"])]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    summary.add_options(parser)
    parser.add_argument("--checkpoint", type=Path, help="an OmniD pretrained_model folder")
    parser.add_argument("--levels", default="2", help="cm and degrees, comma-separated")
    parser.add_argument("--draws", type=positive_int, default=10)
    parser.add_argument("--perturbation-seed", type=int, default=0, help="omnid-robustness's (default 0)")
    parser.add_argument("--point", default=",".join(map(str, APPLE)), help="x,y,z m (select_apple's apple)")
    parser.add_argument("--robustness-summary", type=Path, help="an omnid-robustness summary.json")
    parser.add_argument("--label", default="omnid", help="the checkpoint's label in that summary")
    args = parser.parse_args(argv)
    if summary.rebuild(parser, args, PROTOCOL, report_lines):
        return 0
    config_file = args.checkpoint / "config.json" if args.checkpoint else None
    if config_file is None or not config_file.is_file():
        parser.error(
            f"--checkpoint: expected a pretrained_model folder with config.json, got {args.checkpoint}"
        )
    try:
        checkpoint = checkpoint_from_config(
            "checkpoint", args.checkpoint, json.loads(config_file.read_text())
        )
    except ValueError as e:
        parser.error(str(e))
    if not checkpoint.is_omnid:
        parser.error(f"--checkpoint: expected an OmniD checkpoint, got a {checkpoint.policy_type} one")
    levels = csv_of(float, None)(args.levels)
    point = torch.tensor(csv_of(float, None)(args.point), dtype=torch.float64)
    if point.shape != (3,):
        parser.error(f"--point: expected x,y,z (m), got {args.point!r}")
    successes = {}
    if args.robustness_summary:
        try:
            successes = draw_successes(args.robustness_summary, args.label, args.perturbation_seed)
        except ValueError as e:
            parser.error(f"--robustness-summary: {e}")
    draws = []
    for level in levels:
        for draw in range(1, args.draws + 1):
            believed = perturbed_calibrations(
                checkpoint.calibrations, camera_offsets(level, draw, args.perturbation_seed)
            )
            row = {
                "level": level,
                "draw": draw,
                **draw_row(displacements(checkpoint.calibrations, believed, point)),
            }
            if (level, draw) in successes:
                row["successes"], row["episodes"] = successes[(level, draw)]
            draws.append(row)
    settings = {
        "checkpoint": str(args.checkpoint),
        "levels": levels,
        "perturbation_seed": args.perturbation_seed,
        "point": point.tolist(),
    }
    summary.finish(args, PROTOCOL, MODULE, argv, settings, {"draws": draws}, code_commit(), report_lines)
    measured = [d for d in draws if "successes" in d]
    if measured:
        shift_chart(measured, args.out / CHART)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
