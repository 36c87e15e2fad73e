"""OmniD against LeRobot's DP on MetaWorld, a benchmark we did not write, beside the published numbers.

The protocol (docs/benchmark.md#metaworld-its-protocol), fixed before any of its runs, follows the 3D
Diffusion Policy paper's MetaWorld protocol where a CPU allows:

1. *Data*: per task of ``TASKS`` (the five with published per-task numbers), 10 expert demonstrations
   (MetaWorld's scripted policy through ``omnid-record --suite metaworld``, env seeds 0-9, all successful),
   cameras ``corner``, ``corner2``, ``corner3`` and the hand camera ``behindGripper`` (calibrated per
   frame), ``IMAGE_SIZE`` px.
2. *Models* (``MODELS``), each trained with ``lerobot-train --seed=1000`` for ``STEPS`` steps with the
   benchmark's ``mini`` options (``methods.method_flags``): OmniD on the four cameras; OmniD on the three
   fixed cameras (what the moving camera adds); DP on the same four cameras; DP on ``corner2`` alone, the
   published setting (one camera), the bridge to the published numbers. OmniD's volume is MetaWorld's
   workspace in MetaWorld's frame (``VOLUME_BOUNDS``).
3. *Test*: ``lerobot-eval`` on env seeds ``TEST_SEEDS`` (``TEST_EPISODES`` each; disjoint from the
   demonstrations' 0-9), episodes of at most ``EPISODE_LENGTH`` steps; every model's blind control (every
   camera black) on the same seeds. Reported: the final checkpoint's success (mean of final), Wilson 95 %
   intervals, Fisher p of OmniD against each DP; the published numbers (DP3 paper, best 5 evaluations of
   3 seeds, MetaWorld v2, 84 px, one camera) only beside them, labelled as such.

Runs on the experiment engine (resumable; ``--dry-run`` prints every command); writes ``<out>/report.md``
(with its chart ``metaworld.png``) and ``<out>/summary.json``; ``--report-only --summary FILE...``
rebuilds the report from such summaries alone, merged: a run split by ``--tasks`` over several folders or
machines is reported as one.

    MUJOCO_GL=egl python -m lerobot_omnid.benchmark.metaworld_comparison --out outputs/metaworld
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from gym_omnid.metaworld_suite import DEFAULT_CAMERAS, FIXED_CAMERAS, STATE_DIM

from lerobot_omnid.benchmark import commands
from lerobot_omnid.benchmark.methods import input_features, method_flags
from lerobot_omnid.benchmark.plan import MINI, TRAIN_SEED
from lerobot_omnid.cli import csv_of
from lerobot_omnid.measure.across_tasks import NOT_ABOVE_BLIND, pooled_comparison, task_table
from lerobot_omnid.measure.charts import draw_panel, pyplot, save_figure
from lerobot_omnid.measure.engine import CHECKPOINT, Run, evaluations, plan, protocol_main
from lerobot_omnid.measure.report import MISSING, format_rate, markdown_table, write_markdown
from lerobot_omnid.measure.results import CellResult, Key, RunSummary, collect

TASKS = ("assembly-v3", "disassemble-v3", "stick-push-v3", "push-v3", "pick-place-wall-v3")
PROTOCOL = "metaworld_comparison"
PUBLISHED = {  # task: (DP3, image-based Diffusion Policy) success %, DP3 paper Tables I and XVIII
    "assembly-v3": (99, 15),
    "disassemble-v3": (69, 43),
    "stick-push-v3": (97, 63),
    "push-v3": (51, 30),
    "pick-place-wall-v3": (35, 5),
}
DEMONSTRATIONS = 10
IMAGE_SIZE = 64  # px: the benchmark's mini size (the published image DP: 84)
STEPS = 2000
EPISODE_LENGTH = 300  # env steps at 80 Hz: 1.5x the slowest expert episode (disassemble, 206 steps)
TEST_SEEDS = (1000, 2000)  # two disjoint ranges of env seeds, reported apart and pooled
TEST_EPISODES = 15  # per range: 30 per cell
VOLUME_BOUNDS = "[[-0.35,0.45],[0.35,0.95],[-0.05,0.35]]"  # MetaWorld's frame: x right, y forward, z up (m)
VOLUME_SHAPE = "[16,12,8]"  # 5 cm cells
BACKBONE_LAYER = 3  # OmniD's feature stage: mini's (stride 16, 4x4 maps at 64 px)


@dataclass(frozen=True)
class Model:
    """What a model of a MetaWorld protocol is: its LeRobot policy type, its cameras and (OmniD) the last
    ResNet stage whose features it samples."""

    policy: str
    cameras: tuple[str, ...]
    backbone_layer: int = BACKBONE_LAYER


CHOSEN_STAGE = 2  # OmniD's ResNet stage, chosen on validation seeds (metaworld_validation)
MODELS = {
    "omnid_layer2": Model("omnid", DEFAULT_CAMERAS, backbone_layer=CHOSEN_STAGE),
    "omnid_fixed_layer2": Model("omnid", FIXED_CAMERAS, backbone_layer=CHOSEN_STAGE),
    "dp": Model("diffusion", DEFAULT_CAMERAS),
    "dp_corner2": Model("diffusion", ("corner2",)),
    # At mini's stage, as the protocol first trained OmniD: push-v3 only, beside the chosen stage's.
    "omnid": Model("omnid", DEFAULT_CAMERAS),
    "omnid_fixed": Model("omnid", FIXED_CAMERAS),
}
DEFAULT_MODELS = ("omnid_layer2", "omnid_fixed_layer2", "dp", "dp_corner2")
BASES = ("omnid_layer2", "omnid")  # the OmniD the others are compared with: the first measured
LABELS = {
    "omnid_layer2": "OmniD",
    "omnid_fixed_layer2": "OmniD, fixed cameras",
    "dp": "DP",
    "dp_corner2": "DP, corner2",
    "omnid": "OmniD, stride 16",
    "omnid_fixed": "OmniD, fixed cameras, stride 16",
}
CHART = "metaworld.png"


def data_dir(out: Path, task: str) -> Path:
    return out / "data" / task


def record(out: Path, task: str) -> list[str]:
    root = data_dir(out, task)
    return [
        str(commands.BIN / "omnid-record"),
        *("--suite", "metaworld", "--task", task, "--episodes", str(DEMONSTRATIONS)),
        *("--cameras", ",".join(DEFAULT_CAMERAS), "--image-size", str(IMAGE_SIZE), "--seed", "0"),
        *("--root", str(root), "--repo-id", f"local/{root.name}"),
    ]


def train(out: Path, name: str, model: Model, task: str) -> list[str]:
    """``lerobot-train`` of ``model`` (``name`` names its folder) on ``task``'s demonstrations: mini's
    options, this suite's cameras, state size and (OmniD) volume and feature stage."""
    flags = [f"--policy.type={model.policy}", "--policy.device=cpu", "--policy.push_to_hub=false"]
    for flag, _ in method_flags(model.policy, MINI):
        option = flag.partition("=")[0]
        if option in ("--policy.cameras", "--policy.volume_bounds", "--policy.volume_shape"):
            continue
        flags.append(f"{option}={model.backbone_layer}" if option == "--policy.backbone_layer" else flag)
    if model.policy == "omnid":
        flags += [f"--policy.cameras={commands.json_list(model.cameras)}"]
        flags += [f"--policy.volume_bounds={VOLUME_BOUNDS}", f"--policy.volume_shape={VOLUME_SHAPE}"]
    else:  # only the state and these images: the dataset's calibration columns are no input of DP
        features = input_features(model.cameras, IMAGE_SIZE, STATE_DIM)
        flags.append(f"--policy.input_features={features}")
    return commands.train_command(
        data_dir(out, task),
        out / "train" / name / task,
        flags,
        STEPS,
        MINI.batch_size,
        seed=TRAIN_SEED,
    )


def eval_dir(out: Path, name: str, task: str, seed: int, blind: bool, stage: str = "eval") -> Path:
    """Where an evaluation of ``stage`` ("eval": the test; a validation names its own) is written."""
    return out / (f"{stage}_blind" if blind else stage) / name / task / f"seed{seed}"


def evaluate(
    out: Path, name: str, model: Model, task: str, seed: int, blind: bool, episodes: int, folder: Path
) -> list[str]:
    cameras = ",".join(model.cameras)
    cmd = [
        str(commands.BIN / "lerobot-eval"),
        f"--policy.path={out / 'train' / name / task / CHECKPOINT}",
        "--policy.device=cpu",
        "--env.type=omnid_metaworld",
        f"--env.task={task}",
        f"--env.cameras=[{cameras}]",
        f"--env.image_size={IMAGE_SIZE}",
        f"--env.episode_length={EPISODE_LENGTH}",
        f"--eval.n_episodes={episodes}",
        f"--eval.batch_size={MINI.eval_batch_size}",
        f"--seed={seed}",
        f"--output_dir={folder}",
    ]
    return [*cmd, f"--env.blackout_cameras=[{cameras}]"] if blind else cmd


def protocol(
    out: Path,
    tasks: Sequence[str],
    models: Mapping[str, Model],
    seeds: Sequence[int] = TEST_SEEDS,
    episodes: int = TEST_EPISODES,
    stage: str = "eval",
) -> list[Run]:
    """Per task: record, then per model train and evaluate (and its blind control) on every range of
    ``episodes`` env seeds from each of ``seeds``."""
    runs: list[Run] = []
    for task in tasks:
        recorded = Run(f"record/{task}", "record", tuple(record(out, task)), data_dir(out, task))
        runs.append(recorded)
        for name, model in models.items():
            trained = f"train/{name}/{task}"
            cmd = tuple(train(out, name, model, task))
            runs.append(Run(trained, "train", cmd, out / "train" / name / task, (recorded.name,)))
            for seed in seeds:
                for blind in (False, True):
                    folder = eval_dir(out, name, task, seed, blind, stage)
                    cmd = tuple(evaluate(out, name, model, task, seed, blind, episodes, folder))
                    cell = {"result": (name, task, "id"), "seed": seed, "train_seed": TRAIN_SEED}
                    cell["control"] = "blind" if blind else ""
                    runs.append(Run(str(folder.relative_to(out)), "eval", cmd, folder, (trained,), **cell))
    return plan(runs, out)


def summarise(runs: Sequence[Run], commit: str | None = None) -> RunSummary:
    """Every finished evaluation of this plan: model, task, control, env-seed range, counts, commit."""
    settings = {
        "steps": STEPS,
        "demonstrations": DEMONSTRATIONS,
        "image_size": IMAGE_SIZE,
        "episode_length": EPISODE_LENGTH,
        "test_seeds": list(TEST_SEEDS),
    }
    return RunSummary(PROTOCOL, settings, evaluations(runs), {"published": PUBLISHED}, commit)


def write_report(summary: RunSummary, path: Path) -> None:
    """``report.md`` and its chart ``metaworld.png`` beside it: per task and model the success pooled over
    the test ranges and in each, its blind control (cells not above it marked), OmniD's difference to each
    model with Fisher p and, pooled over the tasks, Mantel-Haenszel p and the tasks' heterogeneity; then
    ours beside the published numbers, per task and their mean."""
    records, settings, published = summary.evaluations, summary.settings, summary.results["published"]
    cells = collect(records)
    models = [m for m in MODELS if any(r.key[0] == m for r in records)]
    tasks = [t for t in PUBLISHED if any(r.key[1] == t for r in records)]
    base = next((m for m in BASES if m in models), None)
    lines = [
        "# MetaWorld: OmniD against LeRobot's DP (final checkpoint), published numbers beside",
        "",
        f"{settings['demonstrations']} demonstrations per task, {settings['image_size']} px, "
        f"{settings['steps']} training steps, episodes of at most {settings['episode_length']} steps; test "
        f"env seeds from {', '.join(map(str, settings['test_seeds']))} (the ranges). Cells: success (%) with "
        f"its Wilson 95 % interval; {NOT_ABOVE_BLIND}: not above its blind control (every camera black).",
        "",
        *task_table(records, models, tasks, LABELS, base=base, controls=("blind",)),
    ]
    if base is not None and len(models) > 1 and len(tasks) > 1:
        lines += [
            "",
            f"{LABELS[base]} against each model over the tasks:",
            "",
            *pooled_comparison(records, models, tasks, LABELS, base),
        ]
    lines += ["", *published_table(cells, models, tasks, published)]
    lines += ["", f"![success per task, published image DP marked]({CHART})"]
    write_markdown(lines, path)
    chart(cells, models, tasks, published, path.parent / CHART)


def published_table(
    cells: Mapping[Key, CellResult], models: Sequence[str], tasks: Sequence[str], published: Mapping
) -> list[str]:
    """Ours (the final checkpoint, mean of final) beside the published (best 5 evaluations of 3 seeds,
    MetaWorld v2, one 84 px camera) success (%), per task and the mean over ``tasks``."""
    rows = []
    for task in tasks:
        ours = [format_rate(c) if (c := cells.get((m, task, "id"))) else MISSING for m in models]
        rows.append([task, *ours, *(f"{v}" for v in published[task])])
    if len(tasks) > 1:
        means = []
        for m in models:
            found = [cells[(m, t, "id")].rate for t in tasks if (m, t, "id") in cells]
            means.append(f"{sum(found) / len(found):.1f}" + ("" if len(found) == len(tasks) else "*"))
        rows.append(
            [
                f"mean of {len(tasks)}",
                *means,
                *(f"{sum(published[t][i] for t in tasks) / len(tasks):.1f}" for i in (0, 1)),
            ]
        )
    header = ["Task: success (%)", *(f"{LABELS[m]}, ours" for m in models)]
    header += ["DP3, published", "image DP, published"]
    return markdown_table(header, rows)


def chart(
    cells: Mapping[Key, CellResult],
    models: Sequence[str],
    tasks: Sequence[str],
    published: Mapping,
    path: Path,
) -> Path:
    """Bars of each model's success per task with Wilson intervals; the published image DP's as a dashed
    line over its task (another protocol: orientation, not comparison)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(11, 3.6))
    draw_panel(
        ax, ("MetaWorld, final checkpoint", [(t, t, "id") for t in tasks], list(models)), cells, LABELS
    )
    for i, task in enumerate(tasks):
        label = "image DP, published (v2, best 5 of 3 seeds)" if i == 0 else None
        ax.plot([i - 0.45, i + 0.45], [published[task][1]] * 2, "k--", linewidth=1, label=label)
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
    return save_figure(fig, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/metaworld"))
    parser.add_argument(
        "--tasks", type=csv_of(str, TASKS), default=TASKS, help=f"subset of {','.join(TASKS)} (default all)"
    )
    parser.add_argument(
        "--models",
        type=csv_of(str, MODELS),
        default=DEFAULT_MODELS,
        help=f"subset of {','.join(MODELS)} (default {','.join(DEFAULT_MODELS)})",
    )
    return protocol_main(
        parser,
        argv,
        PROTOCOL,
        lambda args, out: protocol(out, args.tasks, {m: MODELS[m] for m in args.models}),
        summarise,
        write_report,
    )


if __name__ == "__main__":
    raise SystemExit(main())
