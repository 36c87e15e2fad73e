"""What ``omnid-benchmark`` writes from the finished runs of its plan: ``summary.json`` (this folder's
evaluations), ``report.md`` (settings, the paper's tables with Wilson intervals, OmniD against each method
with Fisher tests, the controls, the position-shift curve, the open-loop diagnostic, every run),
``benchmark.png`` and ``position_curve.png`` (:mod:`lerobot_omnid.measure.charts`) and ``results.json``.
Results of other folders (their ``summary.json``, e.g. copied under ``docs/results/``) are merged in.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from gym_omnid.constants import POSITION_BANDS, TRAIN_CAMERAS

from lerobot_omnid.benchmark.methods import (
    ABLATIONS,
    CONTROL_LABELS,
    CONTROLS,
    METHODS,
    VQBET_CAMERA,
    FewshotRecipe,
    ablation_flags,
    control_flags,
    fewshot_model,
    finetune_flags,
    method_controls,
    method_flags,
    recipe_flags,
)
from lerobot_omnid.benchmark.plan import (
    BACKGROUND_OODS,
    BANDS,
    EVAL_SEED_STRIDE,
    FEWSHOT,
    FEWSHOT_SEED,
    HELDOUT_SEED,
    MULTITASK,
    MULTITASK_METHODS,
    OFFLINE_OUTPUT,
    PROBE_PROTOCOL,
    PROBE_SET,
    RIG_SETTINGS,
    SETTINGS,
    TASK0,
    TASK1,
    BenchmarkProfile,
    control_setting,
    heldout_settings,
    multitask,
    multitask_steps,
    seed_folder,
    zero_shot_options,
)
from lerobot_omnid.benchmark.variant_selection import selection_lines
from lerobot_omnid.measure import across_tasks, charts, report, results
from lerobot_omnid.measure.across_tasks import ALPHA, NOT_ABOVE_BLIND
from lerobot_omnid.measure.engine import Run, eval_entry, is_done
from lerobot_omnid.measure.report import MISSING
from lerobot_omnid.measure.stats import fisher_exact, rate_difference

PROBES = "probes"
"""Key, in a benchmark summary's results, of its few-shot probes: each run's fingerprint, training seed and
its models' errors (``probe_cm``, and ``mean_cm`` for predicting the training mean)."""
BANDS_CM = {band: (100 * low, 100 * high) for band, (low, high) in POSITION_BANDS.items()}
"""The graded position bands: distance outside the training square, cm."""
PAPER_TABLE_1 = {  # ID success (%), multi-view B-E, the paper's VLABench fork (not these envs)
    "select_apple": {"omnid": 96, "diffusion": 96, "act": 52, "vqbet": 8},
    "add_condiment": {"omnid": 100, "diffusion": 100, "act": 86, "vqbet": 26},
    "select_chemistry_tube": {"omnid": 100, "diffusion": 70, "act": 94, "vqbet": 66},
    "get_coffee": {"omnid": 94, "diffusion": 88, "act": 0, "vqbet": 90},
    "set_study_table": {"omnid": 56, "diffusion": 48, "act": 0, "vqbet": 40},
    "texas_holdem": {"omnid": 100, "diffusion": 90, "act": 28, "vqbet": 68},
}
"""The paper's Table 1, for orientation beside the six-task table (their average: OmniD 91.0, DP 82.0)."""


def steps_text(p: BenchmarkProfile) -> str:
    """The training steps: the profile's, with the tasks sized otherwise (``task_steps``) named."""
    sized = ", ".join(f"{task} {steps}" for task, steps in p.task_steps if steps != p.steps)
    return f"{p.steps} ({sized})" if sized else str(p.steps)


def settings_markdown(p: BenchmarkProfile, tasks: tuple[str, ...]) -> list[str]:
    """What is run and how, with every non-default option and its reason."""
    labels = p.labels
    evals = ", ".join(f"{k} (env seeds {k * EVAL_SEED_STRIDE}+)" for k in p.eval_seeds)
    where = "every task" if p.every_task else TASK0
    parts = [f"settings {', '.join(p.settings)} on {where}"]
    parts += ["few-shot on camera A"] if p.fewshot else []
    parts += ["ablations"] if p.ablations else []
    folders = ", ".join(f"{s} (runs in `./{seed_folder(Path(), s)[1]}`)" for s in p.train_seeds)
    lines = [
        f"Profile `{p.name}` on `{p.device}`: methods {', '.join(labels[m] for m in p.methods)}; "
        f"tasks {', '.join(tasks)}; {', '.join(parts)}.",
        "",
        f"- Same for every method: datasets of {p.episodes} expert episodes per task (cameras B-E, "
        f"{p.image_size}x{p.image_size} px, env seeds from 0), {steps_text(p)} training steps, "
        f"batch {p.batch_size}; evaluation: {p.eval_episodes} episodes per setting and eval seed, eval seeds "
        f"{evals}, at most {p.episode_length} env steps (10 per second), {p.eval_batch_size} envs at once "
        "(`--eval.batch_size`; episode i keeps env seed start + i).",
        "- Training seeds (the `--seed` of every `lerobot-train`, each a full repetition of the training "
        f"runs and their evaluations on the same datasets and env seeds): {folders}.",
        (
            f"- Controls on {where}, the same checkpoint evaluated in the settings "
            f"{', '.join(p.control_settings)}: blind (only the state can drive it) for every method"
            + "".join(f", {CONTROL_LABELS[c]} for OmniD" for c in p.controls if c != "blind")
            + "; a background OOD's blind control is the ID one's (same env seeds and layouts; a blind "
            "policy sees no table)."
            if p.control_settings
            else f"- Controls on {where}: none for the models trained on cameras B-E."
        ),
        "- Position-shift curve: the graded bands "
        + ", ".join(f"`{b}` ({low:g}-{high:g} cm)" for b, (low, high) in BANDS_CM.items() if b in p.settings)
        + " outside the training square, L-inf; same success rule."
        if any(b in p.settings for b in BANDS)
        else "- Position-shift curve: no band in this run's settings.",
        f"- Few-shot: the task-0 model fine-tuned for {p.finetune_steps} steps on {p.fewshot_episodes} "
        f"camera-A episodes (env seeds from {FEWSHOT_SEED}) of {TASK0} and of {TASK1}, evaluated with "
        "camera A, beside its blind control (the fine-tuned checkpoint with camera A turned away in its "
        "calibration for OmniD, black for the others)."
        + "".join(
            f" Also by the recipe `{r.name}` ({r.label}), its models a row of their own."
            for r in p.fewshot_recipes
            if r.name
        )
        if p.fewshot
        else "- Few-shot fine-tuning: not in this profile.",
        f"- One model for every task: OmniD and DP trained on the {len(tasks)} tasks' training sets together "
        "(the same episodes, recorded with the task as a one-hot in `observation.environment_state`, merged "
        f"with `lerobot-edit-dataset`) for {multitask_steps(p, tasks)} steps, the single-task models' "
        "together; evaluated on every task in ID with the one-hot (`--env.task_onehot=true`) beside its "
        "blind control."
        if multitask(p, tasks)
        else "- One model for every task: not in this profile.",
        "- Cells pool the episodes of all eval and training seeds: success rate (%) with its Wilson 95 % "
        "interval; differences in percentage points with Newcombe's hybrid score interval; p: two-sided "
        "Fisher exact test. `—`: not run (yet).",
        f"- Open-loop diagnostic: {p.heldout_episodes} held-out expert episodes per {TASK0} setting "
        "(the graded bands excepted)."
        if p.heldout_episodes
        else "- Open-loop diagnostic: off.",
        "",
        "| Method | Option | Why |",
        "| --- | --- | --- |",
    ]
    rows = [(labels[m], f, why) for m in p.methods for f, why in method_flags(m, p)]
    if p.control_settings:
        for m in p.methods:
            cameras = VQBET_CAMERA if m == "vqbet" else TRAIN_CAMERAS
            for control in (c for c in method_controls(m) if c in p.controls):
                flags = control_flags(m, control, cameras, "<control calibration file>")
                rows += [(f"{labels[m]} {CONTROL_LABELS[control]}", f, why) for f, why in flags]
    if p.ablations:
        base = {f for f, _ in method_flags("omnid", p)}
        rows += [(labels[a], f, why) for a in ABLATIONS for f, why in ablation_flags(a, p) if f not in base]
    seen: set[tuple[str, str]] = set()
    for v in p.variants:
        rows += [(v.label, f, "as above" if (f, why) in seen else why) for f, why in v.flags]
        seen.update(v.flags)
    if p.fewshot:
        for m in p.methods:
            base_tuning = finetune_flags(m)
            rows += [(f"{labels[m]} fine-tune", f, why) for f, why in base_tuning]
            for recipe in (r for r in p.method_recipes(m) if r.name):
                who = labels[fewshot_model(m, recipe)]
                if recipe.steps == 0:
                    rows.append((who, "no fine-tuning", f"the start model on camera A as is, {TASK0} only"))
                    why = "camera A alone, its true calibration read from every frame"
                    rows += [(who, f, why) for f in zero_shot_options(m)]
                    continue
                if recipe.steps:
                    rows.append((who, f"--steps={recipe.steps}", "the recipe's fine-tuning steps"))
                if recipe.start:
                    rows.append((who, f"--policy.path=<{labels[recipe.start]}>", "the recipe's start"))
                rows += [(who, f, why) for f, why in recipe_flags(m, recipe) if (f, why) not in base_tuning]
    lines += [f"| {who} | `{flag}` | {why} |" for who, flag, why in rows]
    notes = {
        "act": "ACT: one observation step (the only value LeRobot's ACT supports); without pretrained "
        "weights its frozen BatchNorm layers are identities (it has no GroupNorm option); its own optimiser "
        "(AdamW 1e-5, no schedule) is kept.",
        "vqbet": f"VQ-BeT: evaluated with camera {VQBET_CAMERA[0][-1].upper()} only (its single input); "
        "its own optimiser settings are kept.",
    }
    lines += [""] + [f"- {notes[m]}" for m in p.methods if m in notes]
    return lines


def ordered_models(p: BenchmarkProfile, records: Sequence[results.EvalRecord]) -> tuple[str, ...]:
    """The profile's methods and any other method found in merged records, in the paper's order, each
    followed by those of the profile's variants and few-shot recipes of it that have records."""
    found = {r.key[0] for r in records}
    models = []
    for m in METHODS:
        models += [m] if m in p.methods or m in found else []
        models += [v.name for v in p.variants if v.method == m and v.name in found]
        tuned = (fewshot_model(m, r) for r in p.fewshot_recipes if r.name)
        models += [t for t in tuned if t in found]
    return tuple(models)


def comparison_lines(
    records: list[results.EvalRecord],
    methods: Sequence[str],
    tasks: Sequence[str],
    labels: Mapping[str, str],
    recipes: Sequence[FewshotRecipe] = (),
) -> list[str]:
    """OmniD against every other method, cell by cell, with Fisher tests (pooled and per training seed); each
    few-shot recipe's OmniD against the other methods fine-tuned by the same recipe (another method's
    recipe model is compared with no other OmniD)."""
    cells = [(t, s) for t in tasks if t != TASK0 for s in SETTINGS]
    cells = [(TASK0, s) for s in SETTINGS] + cells + [(TASK0, FEWSHOT), (TASK1, FEWSHOT)]
    alike = {fewshot_model(m, r) for m in METHODS if m != "omnid" for r in recipes if r.name}
    lines = [
        "",
        "## OmniD against each method, cell by cell",
        "",
        "Episodes pooled over eval and training seeds; difference with Newcombe's 95 % interval (pp); "
        "two-sided Fisher exact test.",
        "",
        *report.comparison_table(
            records, "omnid", [m for m in methods if m not in {"omnid", *alike}], cells, labels
        ),
    ]
    for recipe in (r for r in recipes if r.name and fewshot_model("omnid", r) in methods):
        others = [fewshot_model(m, recipe) for m in METHODS if m != "omnid"]
        lines += ["", f"Fine-tuned by the recipe `{recipe.name}` ({recipe.label}), each method alike:", ""]
        lines += report.comparison_table(
            records, fewshot_model("omnid", recipe), [o for o in others if o in methods], cells[-2:], labels
        )
    return lines


def fewshot_control_lines(
    records: Sequence[results.EvalRecord], methods: Sequence[str], labels: Mapping[str, str]
) -> list[str]:
    """Each fine-tuned camera-A model against its own blind control, per task (none if not evaluated)."""
    tasks = [t for t in (TASK0, TASK1) if any(r.control and r.key[1:] == (t, FEWSHOT) for r in records)]
    lines = []
    for task in tasks:
        lines += ["", f"## Few-shot on camera A, {task}: each fine-tuned model against its blind control", ""]
        lines += report.controls_table(
            records, methods, task, (FEWSHOT,), {(FEWSHOT, "blind"): FEWSHOT}, labels, {"blind": "blind"}
        )
    return lines


def probe_entry(run: Run) -> dict[str, Any]:
    """A finished probe run as its benchmark summary keeps it (:data:`PROBES`)."""
    models = results.read_run_summary(run.output, PROBE_PROTOCOL).results["models"]
    return {
        "fingerprint": run.fingerprint,
        "train_seed": run.train_seed,
        "models": {model: found["sets"][PROBE_SET] for model, found in models.items()},
    }


def summary_probes(summary: results.RunSummary) -> list[dict[str, Any]]:
    """The probe entries of a benchmark summary (none in one written before it kept them)."""
    return list(summary.results.get(PROBES, []))


def fewshot_probe_lines(probes: Sequence[Mapping[str, Any]], labels: Mapping[str, str]) -> list[str]:
    """Each fine-tuned task-0 model's probe error on fresh camera-A episodes, per training seed, from probe
    entries (:data:`PROBES`; none before a probe run is done)."""
    errors: dict[str, dict[int | None, float]] = {}
    mean = None
    for entry in probes:
        for model, found in entry["models"].items():
            errors.setdefault(model, {})[entry["train_seed"]] = found["probe_cm"]
            mean = found["mean_cm"]
    if not errors:
        return []
    seeds = sorted({s for by_seed in errors.values() for s in by_seed})
    lines = [
        "",
        f"## Few-shot on camera A, {TASK0}: where each fine-tuned model places the apple",
        "",
        "A linear probe of the frozen image condition (`python -m lerobot_omnid.diagnostics."
        "position_extrapolation`), fitted on the camera-A episodes the models were tuned on; its error (cm) "
        f"on fresh camera-A expert episodes; predicting the training mean: {mean:.2f} cm.",
        "",
        "| Model | " + " | ".join(f"training seed {s}" for s in seeds) + " |",
        "| --- |" + " --- |" * len(seeds),
    ]
    for model, by_seed in errors.items():
        cells = [f"{by_seed[s]:.2f}" if s in by_seed else MISSING for s in seeds]
        lines.append(f"| {labels.get(model, model)} | " + " | ".join(cells) + " |")
    return lines


def every_task_lines(
    p: BenchmarkProfile, records: list[results.EvalRecord], methods: Sequence[str], tasks: Sequence[str]
) -> list[str]:
    """Every task with every method beside its controls and per range of env seeds; OmniD against each
    method over the tasks."""
    labels = p.labels
    unseen = next((s for s in p.settings if s in BACKGROUND_OODS), None)
    lines = [
        "",
        "## Every task: each method beside its controls, each range of env seeds",
        "",
        f"Success pooled over the ranges (Wilson 95 %), then each range alone (eval seed k: env seeds "
        f"{EVAL_SEED_STRIDE}k, ...); the controls of the same checkpoint in the same setting; "
        f"{NOT_ABOVE_BLIND}: not above its blind control (higher with Fisher p < {ALPHA:g}); the difference "
        "to OmniD with Newcombe's interval and the two-sided Fisher p (pooled rows: Mantel-Haenszel, "
        "stratified by task).",
        "",
        *across_tasks.task_table(
            records, methods, tasks, labels, setting="id", unseen=unseen, controls=p.controls
        ),
    ]
    if "omnid" in methods and len(methods) > 1 and len(tasks) > 1:
        lines += ["", "## OmniD against each method over the tasks", ""]
        lines += across_tasks.pooled_comparison(records, methods, tasks, labels)
    paper = [t for t in tasks if t in PAPER_TABLE_1]
    if paper:
        lines += [
            "",
            "The paper's Table 1 for orientation (ID success %, its VLABench fork, 3000 expert episodes over "
            "the six tasks at 480 px, 100k training steps on a GPU; here 50 episodes a task at "
            f"{p.image_size} px and {steps_text(p)} CPU steps):",
            "",
            "| Task | " + " | ".join(labels[m] for m in methods) + " |",
            "| --- |" + " --- |" * len(methods),
        ]
        for t in paper:
            lines.append(
                f"| {t} | " + " | ".join(str(PAPER_TABLE_1[t].get(m, MISSING)) for m in methods) + " |"
            )
    together = [m for m in MULTITASK_METHODS if any(r.key[0] == m + MULTITASK for r in records)]
    if together:
        models = [model for m in together for model in (m + MULTITASK, m)]
        lines += [
            "",
            "## One model for every task against one model per task",
            "",
            f"Each method trained on every task together ({multitask_steps(p, tasks)} steps, the single-task "
            "models' together), told the task by a one-hot in `observation.environment_state`; ID per task "
            "beside its blind control, then against the single-task models over the tasks.",
            "",
            *across_tasks.task_table(records, models, tasks, labels, base=None, controls=("blind",)),
        ]
        for m in together:
            lines += ["", *across_tasks.pooled_comparison(records, (m,), tasks, labels, base=m + MULTITASK)]
    return lines


def curve_lines(
    cells: Mapping[results.Key, results.CellResult],
    methods: Sequence[str],
    chart: Path,
    labels: Mapping[str, str],
) -> list[str]:
    """The position-shift curve: its table, the area of each method against OmniD's, the chart."""
    lines = [
        "",
        f"## Task 0 ({TASK0}): success against the distance outside the training square",
        "",
        "Key objects in graded bands outside the 10 cm training square (L-inf distance), same success rule. "
        "Area: the mean success over 0-10 cm (width-weighted mean of the bands); with the same episodes in "
        "every band it is the pooled rate, given with its Wilson interval.",
        "",
        *report.curve_table(cells, methods, TASK0, BANDS_CM, labels),
    ]
    omnid = report.curve_area(cells, "omnid", TASK0, BANDS_CM)
    for m in methods:
        other = report.curve_area(cells, m, TASK0, BANDS_CM)
        if m == "omnid" or omnid is None or other is None or omnid[1] is None or other[1] is None:
            continue
        a, b = omnid[1], other[1]
        difference = report.format_difference(
            rate_difference(a.successes, a.episodes, b.successes, b.episodes)
        )
        p_value = report.format_p(fisher_exact(a.successes, a.episodes, b.successes, b.episodes))
        lines += [
            "",
            f"Area, OmniD - {labels[m]}: {difference} pp, Fisher p = {p_value} (band episodes pooled).",
        ]
    return [*lines, "", f"![position-shift curve]({chart.name})"]


def rig_lines(
    cells: Mapping[results.Key, results.CellResult], methods: Sequence[str], labels: Mapping[str, str]
) -> list[str]:
    """Task 0 on the unseen rigs beside ID, each model's rigs pooled (none before a rig is evaluated)."""
    rigs = [s for s in RIG_SETTINGS if any((m, TASK0, s) in cells for m in methods)]
    if not rigs:
        return []
    rows = []
    for m in (m for m in methods if any((m, TASK0, s) in cells for s in rigs)):
        row = [cells.get((m, TASK0, s)) for s in ("id", *rigs)]
        done = [c for c in row[1:] if c is not None]
        pooled = results.CellResult(sum(c.successes for c in done), sum(c.episodes for c in done), ())
        row_text = [report.format_rate(c) if c else MISSING for c in row]
        rows.append([labels.get(m, m), *row_text, report.format_rate(pooled) if done else MISSING])
    return [
        "",
        f"## Task 0 ({TASK0}): moved rigs, each with its true calibration",
        "",
        "The training rig's layouts seen by cameras moved elsewhere (`gym_omnid.RIGS`); OmniD reads each "
        "rig's calibration from every frame, the others see its images. Success (%, Wilson 95 %).",
        "",
        *report.markdown_table(["Model", "ID", *rigs, "moved rigs pooled"], rows),
    ]


def write_summary(
    p: BenchmarkProfile,
    tasks: tuple[str, ...],
    runs: list[Run],
    out: Path,
    commit: str | None = None,
    command: Sequence[str] = (),
    resumed: results.RunSummary | None = None,
) -> tuple[list[results.EvalEntry], list[results.EvalRecord], list[dict[str, Any]]]:
    """summary.json: the finished evaluations and probes of ``runs`` (cheap: rewritten after every
    evaluation, so that a killed campaign loses nothing done), with those of the ``resumed`` summary (an
    earlier campaign's) that are planned and not done here. Returns every planned evaluation, the records of
    the done and the probe entries."""
    evaluations = [r for r in runs if r.kind == "eval"]
    entries = [eval_entry(r) for r in evaluations]
    done = [is_done(r) for r in evaluations]
    own = [results.record_of(e) for e, made in zip(entries, done, strict=True) if made]
    missing = {r.fingerprint for r, made in zip(evaluations, done, strict=True) if not made}
    probe_runs = [r for r in runs if r.kind == "probe"]
    probes = [probe_entry(r) for r in probe_runs if is_done(r)]
    if resumed is not None:
        own += [r for r in resumed.evaluations if r.fingerprint in missing]
        missing = {r.fingerprint for r in probe_runs if not is_done(r)}
        probes += [e for e in summary_probes(resumed) if e["fingerprint"] in missing]
    out.mkdir(parents=True, exist_ok=True)
    found = {PROBES: probes} if probes else {}
    results.write_summary(out / results.SUMMARY, dataclasses.asdict(p), tasks, own, commit, command, found)
    return entries, own, probes


def write_outputs(
    p: BenchmarkProfile,
    tasks: tuple[str, ...],
    runs: list[Run],
    out: Path,
    also: Sequence[Path] = (),
    commit: str | None = None,
    command: Sequence[str] = (),
    resumed: results.RunSummary | None = None,
) -> dict:
    """summary.json (this folder's evaluations and probes and the ``resumed`` ones), then report.md,
    benchmark.png, position_curve.png and results.json from them and from the summaries of ``also`` (other
    folders or summary files)."""
    entries, own, own_probes = write_summary(p, tasks, runs, out, commit, command, resumed)
    groups = [own]
    probes = {e["fingerprint"]: e for e in own_probes}
    for path in also:
        other = results.read_run_summary(path, results.BENCHMARK)
        results.check_comparable(dataclasses.asdict(p), other.settings["profile"], str(path))
        groups.append(other.evaluations)
        probes |= {e["fingerprint"]: e for e in summary_probes(other)}
    records = results.merge(groups)
    methods = ordered_models(p, records)
    labels = p.labels
    cells = results.collect(records)
    first_seed = p.train_seeds[0]
    offline = {
        r.result: r.output / OFFLINE_OUTPUT
        for r in runs
        if r.kind == "offline" and r.train_seed == first_seed and is_done(r)
    }
    measured = {model for model, _, _ in cells}
    charted = [model for m in methods for model in (m, m + MULTITASK) if model in measured]
    chart = charts.bar_chart(
        cells, charted, tasks, TASK0, TASK1, BACKGROUND_OODS, labels, out / "benchmark.png"
    )
    lines = ["# OmniD benchmark: OmniD vs DP, ACT, VQ-BeT", "", *settings_markdown(p, tasks), ""]
    if also:
        lines += [
            f"Merged with {len(records) - len(own)} evaluations of: " + ", ".join(f"`{a}`" for a in also),
            "",
        ]
    lines += ["## ID success rate (%) per task, cameras B-E", ""]
    lines += report.id_table(cells, methods, tasks, labels)
    if p.every_task:
        lines += every_task_lines(p, records, methods, tasks)
    if TASK0 in tasks:
        lines += ["", f"## Task 0 ({TASK0}): generalisation and few-shot on camera A, success rate (%)", ""]
        lines += report.generalisation_table(cells, methods, TASK0, TASK1, BACKGROUND_OODS, labels)
        if "omnid" in methods and len(methods) > 1:
            lines += comparison_lines(records, methods, tasks, labels, p.fewshot_recipes)
        if any(r.control for r in records):
            control_of = {
                (s, c): control_setting(s, c, p.control_settings) for s in SETTINGS for c in CONTROLS
            }
            lines += ["", f"## Task 0 ({TASK0}): each method against its controls", ""]
            lines += report.controls_table(
                records, methods, TASK0, SETTINGS, control_of, labels, CONTROL_LABELS
            )
        lines += fewshot_control_lines(records, methods, labels)
        lines += fewshot_probe_lines(list(probes.values()), labels)
        lines += rig_lines(cells, methods, labels)
        if any((m, TASK0, b) in cells for m in methods for b in BANDS):
            curve = charts.position_curve_chart(
                cells, methods, TASK0, BANDS_CM, labels, out / "position_curve.png"
            )
            lines += curve_lines(cells, methods, curve, labels)
    if offline:
        lines += [
            "",
            f"## Task 0 ({TASK0}): open-loop action error on held-out expert episodes",
            "",
            f"Diagnostic next to the success rates: {p.heldout_episodes} expert episodes per setting "
            f"(env seeds from {HELDOUT_SEED}, never trained on) replayed through each policy (training seed "
            f"{first_seed}) as `lerobot-eval` runs it (`omnid-offline-eval`); mean TCP position error (cm) / "
            "gripper error (0..1) of its action at every frame against the expert's. Lower is better; "
            "informative even when every success rate is 0. The last row is the error of holding the "
            "measured pose and gripper at every frame: a policy that does not beat it has not learned to act "
            "yet.",
            "",
        ]
        lines += report.offline_table(offline, methods, TASK0, heldout_settings(p, tasks), labels)
    if p.variants and TASK0 in tasks:
        lines += selection_lines(cells, p, labels)
    if p.ablations:
        lines += ["", f"## Ablation: OmniD on task 0 ({TASK0}), ID success rate (%)", ""]
        lines += report.ablation_table(cells, TASK0)
    lines += ["", f"![success rates]({chart.name})", "", "## Evaluation runs", ""]
    lines += report.raw_table(entries, records, labels)
    (out / "report.md").write_text("\n".join(lines) + "\n")

    def cell_json(key: results.Key, cell: results.CellResult, control: str = "") -> dict:
        model, task, setting = key
        interval = cell.interval
        return {
            "model": model,
            "task": task,
            "setting": setting,
            "control": control,
            "successes": cell.successes,
            "episodes": cell.episodes,
            "success_rate": cell.rate,
            "wilson_95": [100 * interval.low, 100 * interval.high],
            "sources": list(cell.sources),
        }

    summary = {
        "profile": dataclasses.asdict(p),
        "tasks": list(tasks),
        "train_seeds": results.train_seeds(records),
        "cells": [cell_json(k, c) for k, c in cells.items()],
        "controls": [
            cell_json(k, c, control)
            for control in CONTROLS
            for k, c in results.collect(records, control).items()
        ],
    }
    (out / "results.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
