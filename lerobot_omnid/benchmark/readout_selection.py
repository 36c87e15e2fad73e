"""Choosing OmniD's plane readout on validation data, then testing only the choice against the paper's.

The protocol (docs/benchmark.md#choosing-the-readout), fixed before any of its runs:

1. *Candidates*: every readout of ``PLANE_READOUTS``, each an OmniD with the benchmark's ``mini`` options
   (``select_apple``, its 50 training episodes, cameras B-E, 64 px, 1000 steps, batch 8,
   ``lerobot-train --seed=1000``) but ``--policy.plane_readout``; ``flatten`` compresses the plane to one
   channel as the paper does, the others keep ``mini``'s 16.
2. *Validation*, never used for a reported number: (a) closed loop, ``lerobot-eval`` in the ID setting on env
   seeds ``VALIDATION_SEED`` ... (20 episodes), disjoint from the training recordings (0 ...), the test
   seeds (1000k, k = 1 .. 49), the few-shot (100000 ...) and the diagnostic's held-out episodes (200000
   ...); (b) open loop, ``omnid-offline-eval`` on 10 expert episodes recorded from env seed
   ``VALIDATION_HELDOUT_SEED``.
3. *Rule* (:func:`select`): the readout with the most validation successes; among those within
   ``TIE_MARGIN`` successes of the most, the lowest open-loop TCP error; written to ``selection.json``.
4. *Test*, only once the selection exists (``--test``): the selected readout and ``flatten``, each on the
   benchmark's test seeds (env seeds 1000 ..., 30 episodes) in ID, on the four unseen tables and in the
   four position bands, with its blind control in ID; Wilson intervals and Fisher tests, selected vs
   flatten. OmniD against DP with the selected readout is then ``omnid-benchmark``'s job.

Runs on the experiment engine (resumable, ``--dry-run`` prints every command); writes ``<out>/report.md``
and ``<out>/summary.json``.

    MUJOCO_GL=egl python -m lerobot_omnid.benchmark.readout_selection --out outputs/readouts \\
        --data outputs/bench_mini/data/select_apple_bcde          # train, validate, select
    MUJOCO_GL=egl python -m lerobot_omnid.benchmark.readout_selection --out outputs/readouts --test
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

from gym_omnid import TRAIN_CAMERAS

from lerobot_omnid.benchmark import commands
from lerobot_omnid.benchmark.methods import control_flags, method_flags
from lerobot_omnid.benchmark.plan import (
    BACKGROUND_OODS,
    BANDS,
    EVAL_SEED_STRIDE,
    OFFLINE_OUTPUT,
    PROFILES,
    TASK0,
    TRAIN_SEED,
    setting_env,
)
from lerobot_omnid.cli import add_protocol_options
from lerobot_omnid.measure.engine import (
    CHECKPOINT,
    Run,
    code_commit,
    describe_plan,
    evaluations,
    execute,
    is_done,
    plan,
    report_from_summary,
)
from lerobot_omnid.measure.report import MISSING, format_counts, write_markdown
from lerobot_omnid.measure.results import (
    SUMMARY,
    RunSummary,
    tags_of,
    write_run_summary,
)
from lerobot_omnid.measure.stats import fisher_exact
from lerobot_omnid.policy.plane_readout import PLANE_READOUTS

PROFILE = PROFILES["mini"]
PROTOCOL = "readout_selection"
PAPER_READOUT = "flatten"
READOUT_CHANNELS = {PAPER_READOUT: 1}  # compressed channels; others keep mini's
VALIDATION_SEED = 50_000  # first env seed of the closed-loop validation episodes
VALIDATION_EPISODES = 20
VALIDATION_HELDOUT_SEED = 300_000  # first env seed of the open-loop validation recording
VALIDATION_HELDOUT_EPISODES = 10
TIE_MARGIN = 1  # validation successes within which the open-loop error decides
TEST_SEED = EVAL_SEED_STRIDE  # the benchmark's eval seed 1: env seeds 1000 ...
TEST_EPISODES = 30
TEST_SETTINGS = ("id", *BACKGROUND_OODS, *BANDS)
SELECTION_FILE = "selection.json"
BLIND_FILE = "blind.json"  # the blind control's calibration file of a readout
TRAIN_DATA = f"{TASK0}_bcde"
HELDOUT_DATA = f"{TASK0}_bcde_validation"


def train(out: Path, data: Path, readout: str, device: str) -> list[str]:
    channels = READOUT_CHANNELS.get(readout)
    flags = ["--policy.type=omnid", f"--policy.device={device}", "--policy.push_to_hub=false"]
    for flag, _ in method_flags("omnid", PROFILE):
        if flag.startswith("--policy.plane_readout="):
            flag = f"--policy.plane_readout={readout}"
        elif flag.startswith("--policy.compressed_channels=") and channels is not None:
            flag = f"--policy.compressed_channels={channels}"
        flags.append(flag)
    return commands.train_command(
        data, out / "train" / readout, flags, PROFILE.steps, PROFILE.batch_size, seed=TRAIN_SEED
    )


def checkpoint(out: Path, readout: str) -> Path:
    return out / "train" / readout / CHECKPOINT


def eval_dir(out: Path, phase: str, readout: str, setting: str, control: str = "") -> Path:
    return out / phase / readout / (f"{setting}_{control}" if control else setting)


def control_file(out: Path, readout: str) -> Path:
    return out / "controls" / readout / BLIND_FILE


def evaluation(out: Path, phase: str, readout: str, setting: str, device: str, control: str = "") -> Run:
    """``lerobot-eval`` of one readout, the cell it fills tagged with its ``phase``: "validation" (ID,
    validation seeds) or "test"."""
    seed, episodes = (
        (VALIDATION_SEED, VALIDATION_EPISODES) if phase == "validation" else (TEST_SEED, TEST_EPISODES)
    )
    layout, background = setting_env(setting)
    extra = [f"--env.episode_length={PROFILE.episode_length}"]
    if control:
        extra += [
            flag for flag, _ in control_flags("omnid", control, TRAIN_CAMERAS, control_file(out, readout))
        ]
    folder = eval_dir(out, phase, readout, setting, control)
    cmd = commands.eval_command(
        checkpoint(out, readout),
        folder,
        TASK0,
        layout,
        TRAIN_CAMERAS,
        PROFILE.image_size,
        episodes,
        device,
        background,
        seed=seed,
        extra=extra,
        batch_size=min(PROFILE.eval_batch_size, episodes),
    )
    name = f"eval/validation/{readout}" if phase == "validation" else f"eval/test/{readout}/{folder.name}"
    needs = (f"train/{readout}", *((f"calibration/{readout}",) if control else ()))
    return Run(
        name,
        "eval",
        tuple(cmd),
        folder,
        needs,
        result=(readout, TASK0, setting),
        seed=seed,
        train_seed=TRAIN_SEED,
        control=control,
        tags=tags_of({"phase": phase}),
    )


def offline(out: Path, readout: str, device: str) -> list[str]:
    cmd = [str(commands.BIN / "omnid-offline-eval"), "--checkpoint", str(checkpoint(out, readout))]
    cmd += ["--root", str(out / "data" / HELDOUT_DATA), "--device", device]
    return [*cmd, "--out", str(out / "offline" / readout / OFFLINE_OUTPUT)]


def validation_runs(out: Path, data: Path, device: str, record_data: bool) -> list[Run]:
    """Record the open-loop validation episodes (and the training set unless given), then per readout:
    train, open-loop error, closed-loop validation."""
    runs = []
    if record_data:
        record = commands.record_command(TASK0, PROFILE.episodes, TRAIN_CAMERAS, PROFILE.image_size, data)
        runs.append(Run(f"record/{TRAIN_DATA}", "record", tuple(record), data))
    inputs = () if record_data else (data / "meta" / "info.json", data / "meta" / "stats.json")
    needs = (f"record/{TRAIN_DATA}",) if record_data else ()
    heldout = out / "data" / HELDOUT_DATA
    record = commands.record_command(
        TASK0,
        VALIDATION_HELDOUT_EPISODES,
        TRAIN_CAMERAS,
        PROFILE.image_size,
        heldout,
        seed=VALIDATION_HELDOUT_SEED,
    )
    runs.append(Run(f"record/{HELDOUT_DATA}", "record", tuple(record), heldout))
    for readout in PLANE_READOUTS:
        trained = f"train/{readout}"
        runs += [
            Run(
                trained,
                "train",
                tuple(train(out, data, readout, device)),
                out / "train" / readout,
                needs,
                inputs=inputs,
            ),
            Run(
                f"offline/{readout}",
                "offline",
                tuple(offline(out, readout, device)),
                out / "offline" / readout,
                (trained, f"record/{HELDOUT_DATA}"),
            ),
            evaluation(out, "validation", readout, "id", device),
        ]
    return runs


def test_runs(out: Path, selected: str, device: str) -> list[Run]:
    """The selected readout and the paper's on the test seeds, each with its blind control in ID."""
    runs = []
    for readout in dict.fromkeys((selected, PAPER_READOUT)):
        trained = f"train/{readout}"
        blind = f"calibration/{readout}"
        cmd = commands.control_calibration_command(
            checkpoint(out, readout), "blind", control_file(out, readout)
        )
        runs.append(Run(blind, "calibration", tuple(cmd), control_file(out, readout), (trained,)))
        runs += [evaluation(out, "test", readout, setting, device) for setting in TEST_SETTINGS]
        runs.append(evaluation(out, "test", readout, "id", device, "blind"))
    return runs


def protocol(out: Path, data: Path, device: str, record_data: bool, selected: str | None) -> list[Run]:
    """The whole plan: validation, and the test of ``selected`` once a selection exists."""
    runs = validation_runs(out, data, device, record_data)
    return plan([*runs, *(test_runs(out, selected, device) if selected else ())], out)


def open_loop_errors(runs: Sequence[Run]) -> dict[str, dict[str, float]]:
    """Per readout whose open-loop run of ``runs`` is done: its TCP (cm) and gripper errors."""
    found = {}
    for run in runs:
        if run.kind == "offline" and is_done(run):
            errors = json.loads((run.output / OFFLINE_OUTPUT).read_text())
            found[run.output.name] = {"position_cm": errors["position_cm"], "gripper": errors["gripper"]}
    return found


def validation_results(runs: Sequence[Run]) -> dict[str, dict]:
    """Per readout whose validation runs of ``runs`` are both done: successes, episodes, open-loop
    errors."""
    errors = open_loop_errors(runs)
    return {
        r.key[0]: {"successes": r.successes, "episodes": r.episodes, **errors[r.key[0]]}
        for r in evaluations(runs)
        if r.tag("phase") == "validation" and r.key[0] in errors
    }


def select(results: dict[str, dict]) -> str:
    """The protocol's rule: most validation successes; among the readouts within ``TIE_MARGIN`` of the most,
    the lowest open-loop TCP error (then the order of ``PLANE_READOUTS``)."""
    best = max(r["successes"] for r in results.values())
    close = [
        name for name in PLANE_READOUTS if name in results and results[name]["successes"] >= best - TIE_MARGIN
    ]
    return min(close, key=lambda name: results[name]["position_cm"])


def report(out: Path, runs: Sequence[Run], commit: str | None = None) -> RunSummary:
    """``report.md`` and ``summary.json`` from the runs of the plan that are done; returns the summary."""
    settings = {
        "task": TASK0,
        "steps": PROFILE.steps,
        "train_seed": TRAIN_SEED,
        "validation_seed": VALIDATION_SEED,
        "heldout_seed": VALIDATION_HELDOUT_SEED,
        "test_seed": TEST_SEED,
    }
    selection = json.loads((out / SELECTION_FILE).read_text()) if (out / SELECTION_FILE).is_file() else None
    results = {"open_loop": open_loop_errors(runs), "selection": selection}
    summary = RunSummary(PROTOCOL, settings, evaluations(runs), results, commit)
    write_run_summary(out / SUMMARY, summary)
    write_report(summary, out / "report.md")
    return summary


def write_report(summary: RunSummary, path: Path) -> None:
    """``report.md`` (validation table with the selection, test table with Fisher tests) from a
    ``summary.json``, this run's or a committed one."""
    selection, open_loop = summary.results["selection"], summary.results["open_loop"]
    test: dict[str, dict[str, tuple[int, int]]] = {}
    validation: dict[str, tuple[int, int]] = {}
    for r in summary.evaluations:
        if r.tag("phase") == "validation":
            validation[r.key[0]] = (r.successes, r.episodes)
        else:
            setting = r.key[2] + ("_blind" if r.control == "blind" else "")
            test.setdefault(r.key[0], {})[setting] = (r.successes, r.episodes)
    test = {r: test[r] for r in PLANE_READOUTS if r in test}
    settings = summary.settings
    lines = [f"# Choosing the plane readout ({settings['task']}, mini sizes)", ""]
    seeds = f"env seeds {settings['validation_seed']}-{settings['validation_seed'] + VALIDATION_EPISODES - 1}"
    lines += [
        f"Validation: ID success on {seeds}; open-loop error on {VALIDATION_HELDOUT_EPISODES} expert "
        f"episodes from env seed {settings['heldout_seed']}. Rule: most successes; within "
        f"{TIE_MARGIN} of the most, the lowest open-loop TCP error.",
        "",
        "| readout | validation success (Wilson 95 %) | open-loop TCP (cm) | gripper | selected |",
        "|---|---|---|---|---|",
    ]
    for name, counts in validation.items():
        chosen = "**yes**" if selection and selection["selected"] == name else ""
        errors = open_loop.get(name)
        position, gripper = (
            (f"{errors['position_cm']:.2f}", f"{errors['gripper']:.3f}") if errors else (MISSING, MISSING)
        )
        lines.append(f"| {name} | {format_counts(counts)} | {position} | {gripper} | {chosen} |")
    if test and selection:
        first = settings["test_seed"]
        lines += [
            "",
            f"Test: env seeds {first}-{first + TEST_EPISODES - 1}, the selected `{selection['selected']}` "
            f"against the paper's `{PAPER_READOUT}`.",
            "",
        ]
        lines += ["| setting | " + " | ".join(test) + " | Fisher p |", "|---|" + "---|" * (len(test) + 1)]
        for setting in (*TEST_SETTINGS, "id_blind"):
            cells = [test[r].get(setting) for r in test]
            p = f"{fisher_exact(*cells[0], *cells[1]):.3g}" if len(cells) == 2 and all(cells) else ""
            lines.append(f"| {setting} | " + " | ".join(map(format_counts, cells)) + f" | {p} |")
        if all(o in test[r] for r in test for o in BACKGROUND_OODS):
            cells = [tuple(sum(test[r][o][i] for o in BACKGROUND_OODS) for i in (0, 1)) for r in test]
            p = f"{fisher_exact(*cells[0], *cells[1]):.3g}" if len(cells) == 2 else ""
            lines.append("| unseen tables, pooled | " + " | ".join(map(format_counts, cells)) + f" | {p} |")
    write_markdown(lines, path)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/readouts"))
    parser.add_argument(
        "--data",
        type=Path,
        help=f"the mini benchmark's training set ({TRAIN_DATA}); default: recorded here",
    )
    parser.add_argument("--device", default="cpu", help="torch device of training and evaluation")
    parser.add_argument(
        "--test", action="store_true", help="evaluate the selected readout and flatten on the test seeds"
    )
    add_protocol_options(parser)
    args = parser.parse_args(argv)
    out = args.out.resolve()
    if report_from_summary(parser, args, out, PROTOCOL, write_report):
        return
    data = args.data.resolve() if args.data else out / "data" / TRAIN_DATA
    if args.data and (found := commands.recorded_episodes(data)) != PROFILE.episodes:
        parser.error(f"--data: expected a dataset of {PROFILE.episodes} episodes, got {found} in {data}")
    selection_file = out / SELECTION_FILE
    selected = read_selection(selection_file)
    if args.test and selected is None and not args.dry_run:
        validation = validation_runs(out, data, args.device, not args.data)
        parser.error(
            f"--test: expected every readout validated ({len(PLANE_READOUTS)}) and selected, got "
            f"{len(validation_results(plan(validation, out)))}"
        )
    runs = protocol(out, data, args.device, not args.data, selected if args.test else None)
    if args.dry_run:
        print("\n".join(describe_plan(runs)))
        return
    commit = code_commit()
    if not args.report_only:
        execute(runs, out, commit=commit, desc="readout selection", stop_on_failure=True)
        results = validation_results(runs)
        if selected is None and len(results) == len(PLANE_READOUTS):
            selection = {"selected": select(results), "rule": select.__doc__, "commit": commit}
            selection_file.write_text(json.dumps(selection, indent=2) + "\n")
    # The test's finished runs are reported whether or not this call asked for them.
    reported = protocol(out, data, args.device, not args.data, selected or read_selection(selection_file))
    report(out, reported, commit)


def read_selection(path: Path) -> str | None:
    return json.loads(path.read_text())["selected"] if path.is_file() else None


if __name__ == "__main__":
    main()
