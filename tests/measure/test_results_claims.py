"""The README's headline numbers against the committed run summaries, and the results pages against
themselves, so that a number edited on a page without a run behind it fails here.

:func:`headline_errors` reads the README's "Headline results" section strictly (a count, interval, p-value
or sentence it cannot find is an error too) and recomputes each from the summaries under ``docs/results/``,
pooled as ``omnid-benchmark --report-only --also`` pools them (``read_summary``, ``check_comparable``,
``merge``, ``collect``), with the package's Wilson interval and Fisher test. ``test_an_edited_readme_fails``
feeds it altered texts to show that it can fail. The other tests check ``docs/results.md`` and
``docs/results/history.md``: every ``k/n (low-high %)`` is the Wilson interval of ``k/n``, every link
resolves, the rebuild commands name committed summaries, and no path of one machine appears.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from dataclasses import astuple
from pathlib import Path

import pytest

from lerobot_omnid.benchmark import metaworld_comparison, robustness
from lerobot_omnid.measure.across_tasks import above
from lerobot_omnid.measure.results import (
    CellResult,
    EvalRecord,
    check_comparable,
    collect,
    merge,
    merge_run_summaries,
    read_run_summary,
    read_summary,
)
from lerobot_omnid.measure.stats import fisher_exact, mantel_haenszel, wilson_interval

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
RESULTS_PAGE = ROOT / "docs" / "results.md"
HISTORY_PAGE = ROOT / "docs" / "results" / "history.md"
DIAGNOSTICS_PAGE = ROOT / "docs" / "results" / "diagnostics.md"
VALIDATION_PAGE = ROOT / "docs" / "results" / "validation.md"
SUMMARIES = ROOT / "docs" / "results"
HEADLINE_SUMMARIES = ("mini_seed1000-1001_eval30_cpu2.json", "mini_seed1002_eval30_cpu2.json")
"""The three-seed OmniD-vs-DP run: docs/results.md's "In distribution" rebuild command pools these."""
FEWSHOT_SUMMARIES = tuple(f"mini-fewshot_seed{seed}_eval30_cpu2.json" for seed in (1000, 1001, 1002))
"""The three-seed few-shot run: docs/results.md's "Few-shot on camera A" rebuild command pools these."""

TASK0 = "select_apple"
TABLES = ("ood1", "ood2", "ood3", "ood4")
BANDS = tuple(f"position_band_{k}" for k in range(1, 5))
ROW_MODELS = {"OmniD": "omnid", "DP": "diffusion"}
"""A headline table row's first word -> the model of its cells."""
COLUMNS = {
    "Task 0 ID": (("id",), ""),
    "blind, ID": (("id",), "blind"),
    "scrambled geometry, ID": (("id",), "scrambled"),
    "4 unseen tables pooled": (TABLES, ""),
    "position bands 0-10 cm": (BANDS, ""),
}
"""A headline table column header -> (the task-0 settings its cells pool, the control)."""
WORDS = {"one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "ten": 10}
COUNT = re.compile(r"^\**(\d+)/(\d+)\** \((\d+(?:\.\d+)?)-(\d+(?:\.\d+)?) %\)$")
"""A headline cell: ``74/90 (73-89 %)``, the count possibly bold."""
P_VALUE = re.compile(r"^\**(< ?)?(\d+(?:\.\d+)?)\**$")
ON_PAGE = re.compile(r"\b(\d+)/(\d+)\**,? \((\d+(?:\.\d+)?)-(\d+(?:\.\d+)?) %\)")
"""A success count with its interval anywhere on a results page: ``12/90 (7.8-21.9 %)``."""
MACHINE_PATHS = ("/work", "/tmp", "/root")


def load(names: Sequence[str]) -> list[EvalRecord]:
    """The evaluations of the summaries, merged as ``omnid-benchmark --report-only --also`` merges them."""
    profile, groups = None, []
    for name in names:
        other, records = read_summary(SUMMARIES / name)
        profile = profile or other
        check_comparable(profile, other, name)
        groups.append(records)
    return merge(groups)


def pooled(
    records: Sequence[EvalRecord],
    model: str,
    settings: Sequence[str],
    control: str = "",
    train_seed: int | None = None,
    task: str = TASK0,
) -> tuple[int, int] | None:
    """(successes, episodes) of ``model`` over ``settings``, or None where the summaries have none of them."""
    cells = collect(records, control, train_seed)
    found = [cells[(model, task, s)] for s in settings if (model, task, s) in cells]
    if not found:
        return None
    return sum(c.successes for c in found), sum(c.episodes for c in found)


def printed(value: float, like: str) -> str:
    """``value`` (a fraction) as a percentage with as many decimals as ``like`` shows."""
    decimals = len(like.split(".")[1]) if "." in like else 0
    return f"{100 * value:.{decimals}f}"


def interval_errors(where: str, text: str, successes: int, episodes: int) -> list[str]:
    """Errors if ``text`` (``k/n (low-high %)``) is not ``successes/episodes`` with its Wilson interval."""
    match = COUNT.match(text)
    if match is None:
        return [f"{where}: expected 'k/n (low-high %)', got {text!r}"]
    k, n, low, high = match.groups()
    if (int(k), int(n)) != (successes, episodes):
        return [f"{where}: the summaries give {successes}/{episodes}, the README {k}/{n}"]
    estimate = wilson_interval(successes, episodes)
    if (printed(estimate.low, low), printed(estimate.high, high)) != (low, high):
        expected = f"{printed(estimate.low, low)}-{printed(estimate.high, high)}"
        return [f"{where}: Wilson 95 % interval of {k}/{n} is {expected} %, the README says {low}-{high} %"]
    return []


def p_errors(where: str, text: str, p: float) -> list[str]:
    """Errors if ``text`` (``0.021``, ``< 0.0001``, possibly bold) does not state the p-value ``p``."""
    match = P_VALUE.match(text)
    if match is None:
        return [f"{where}: expected a p-value, got {text!r}"]
    below, value = match.groups()
    decimals = len(value.split(".")[1]) if "." in value else 0
    if below and not p < float(value):
        return [f"{where}: Fisher p = {p:.2g}, the README says < {value}"]
    if not below and abs(p - float(value)) > 0.5 * 10**-decimals:
        return [f"{where}: Fisher p = {p:.2g}, the README says {value}"]
    return []


def assert_each_edit_is_caught(
    check: Callable[[str, Sequence[EvalRecord]], list[str]],
    records: Sequence[EvalRecord],
    edits: Sequence[tuple[str, str]],
) -> None:
    """``check`` finds no error in the README and at least one in each edit of it: the check can fail."""
    readme = README.read_text()
    assert check(readme, records) == []
    for old, new in edits:
        edited = readme.replace(old, new)
        assert edited != readme, f"the README no longer contains {old!r}: update this edit"
        assert check(edited, records) != [], f"editing {old!r} -> {new!r} went unnoticed"


def headline_section(readme: str) -> str:
    match = re.search(r"^## Headline results\n(.*?)(?=^## |\Z)", readme, re.MULTILINE | re.DOTALL)
    return match.group(1) if match else ""


def table_errors(section: str, records: Sequence[EvalRecord]) -> list[str]:
    """The headline table: every cell's count and interval, every blank cell, the p row."""
    rows = [
        [cell.strip() for cell in line.strip().strip("|").split("|")]
        for line in section.splitlines()
        if line.startswith("|") and not set(line) <= set("|- ")
    ]
    if not rows or rows[0][0] != "Method":
        return ["headline table: expected a table whose first column is 'Method', found none"]
    header, body = rows[0], rows[1:]
    errors = [f"headline table: unknown column {h!r}" for h in header[1:] if h not in COLUMNS]
    stated: dict[str, dict[str, tuple[int, int]]] = {}
    p_row = None
    for row in body:
        first = row[0].split()[0] if row[0] else ""
        if row[0] == "p":
            p_row = row
        elif first in ROW_MODELS:
            model = ROW_MODELS[first]
            stated[model] = {}
            for column, cell in zip(header[1:], row[1:], strict=True):
                if column not in COLUMNS:
                    continue
                settings, control = COLUMNS[column]
                truth = pooled(records, model, settings, control)
                where = f"headline table, {first}, {column!r}"
                if truth is None and cell:
                    errors.append(f"{where}: the summaries have no such evaluation, the README {cell!r}")
                elif truth is None:
                    continue
                elif not cell:
                    errors.append(f"{where}: blank, the summaries give {truth[0]}/{truth[1]}")
                else:
                    errors += interval_errors(where, cell, *truth)
                    stated[model][column] = truth
        else:
            errors.append(f"headline table: unknown row {row[0]!r}")
    errors += [f"headline table: no {name} row" for name, m in ROW_MODELS.items() if m not in stated]
    if p_row is None:
        return [*errors, "headline table: no p row"]
    for column, cell in zip(header[1:], p_row[1:], strict=True):
        omnid, dp = stated.get("omnid", {}).get(column), stated.get("diffusion", {}).get(column)
        if cell and omnid and dp:
            errors += p_errors(f"headline table, p, {column!r}", cell, fisher_exact(*omnid, *dp))
        elif cell:
            errors.append(f"headline table, p, {column!r}: a p-value without both methods' counts")
    return errors


def claim(text: str, pattern: str, errors: list[str]) -> re.Match | None:
    """The README sentence ``pattern`` (whitespace-normalised), or an error saying it is gone."""
    match = re.search(pattern, text)
    if match is None:
        errors.append(f"headline: expected a sentence matching {pattern!r}, found none")
    return match


def counts(
    records: Sequence[EvalRecord],
    model: str,
    settings: Sequence[str],
    control: str = "",
    train_seed: int | None = None,
) -> tuple[int, int]:
    """:func:`pooled` for a sentence that needs the cell: a KeyError naming it where the summaries lack it."""
    found = pooled(records, model, settings, control, train_seed)
    if found is None:
        raise KeyError(f"{model} {settings} control {control or 'none'} training seed {train_seed}")
    return found


def headline_errors(readme: str, records: Sequence[EvalRecord], fewshot: Sequence[EvalRecord]) -> list[str]:
    """Everything the README's headline section states that the summaries do not give (empty: all agree)."""
    section = headline_section(readme)
    if not section:
        return ["README: expected a '## Headline results' section, found none"]
    errors = table_errors(section, records)
    try:
        errors += sentence_errors(" ".join(section.split()), records, fewshot)
    except KeyError as e:
        errors.append(f"headline: a sentence needs an evaluation the summaries lack: {e}")
    return errors


def sentence_errors(text: str, records: Sequence[EvalRecord], fewshot: Sequence[EvalRecord]) -> list[str]:
    """The headline's sentences (``text``: whitespace-normalised) against the summaries."""
    errors: list[str] = []
    seeds = sorted({r.train_seed for r in records})
    episodes = {r.episodes for r in records}

    if m := claim(text, r"Below: (\w+) training seeds, (\d+) episodes per cell and seed", errors):
        if WORDS.get(m[1]) != len(seeds):
            errors.append(f"headline: '{m[1]} training seeds', the summaries have {seeds}")
        if episodes != {int(m[2])}:
            errors.append(f"headline: {m[2]} episodes per cell and seed, the summaries {sorted(episodes)}")
    m = claim(text, r"--train-seeds ([\d,]+) --eval-episodes (\d+)", errors)
    if m and ([int(s) for s in m[1].split(",")] != seeds or episodes != {int(m[2])}):
        errors.append(f"headline command: --train-seeds {m[1]} --eval-episodes {m[2]}; summaries {seeds}")
    if m := claim(text, r"Both beat their blind controls \(p < ([\d.]+)\)", errors):
        for model in ROW_MODELS.values():
            p = fisher_exact(*counts(records, model, ("id",)), *counts(records, model, ("id",), "blind"))
            if not p < float(m[1]):
                errors.append(f"headline: {model} over its blind control p = {p:.2g}, not < {m[1]}")
    if m := claim(text, r"OmniD fails (\d+)/(\d+) episodes with its calibrations permuted", errors):
        k, n = counts(records, "omnid", ("id",), "scrambled")
        if (int(m[1]), int(m[2])) != (n - k, n):
            errors.append(f"headline: OmniD fails {m[1]}/{m[2]} scrambled, the summaries {n - k}/{n}")
    if m := claim(text, r"keeps (\d+)/(\d+) with every camera 2 cm and 2 degrees off", errors):
        truth = counts(records, "omnid", ("id",), "perturbed")
        if (int(m[1]), int(m[2])) != truth:
            errors.append(f"headline: OmniD keeps {m[1]}/{m[2]} perturbed, the summaries {truth}")
    if claim(text, r"OmniD leads in distribution at each seed", errors):
        for seed in seeds:
            omnid, dp = (counts(records, model, ("id",), train_seed=seed) for model in ("omnid", "diffusion"))
            if not omnid[0] > dp[0]:
                errors.append(f"headline: OmniD leads at each seed, but seed {seed}: {omnid} vs DP {dp}")
    if m := claim(text, r"on unseen tables at (\w+) seeds of (\w+)", errors):
        tables = {
            s: [counts(records, model, TABLES, train_seed=s)[0] for model in ("omnid", "diffusion")]
            for s in seeds
        }
        ahead = sum(omnid > dp for omnid, dp in tables.values())
        if (WORDS.get(m[1]), WORDS.get(m[2])) != (ahead, len(seeds)):
            errors.append(f"headline: tables '{m[1]} seeds of {m[2]}', the summaries {ahead} of {len(seeds)}")
    if claim(text, r"Neither generalises in position beyond the first band", errors):
        for model in ROW_MODELS.values():
            if counts(records, model, BANDS[1:])[0] != 0:
                errors.append(f"headline: {model} succeeds beyond the first position band")
    pattern = r"camera A \(OmniD (\d+)/(\d+), DP (\d+)/(\d+), p = ([\d.]+); neither above its blind control\)"
    if m := claim(text, pattern, errors):
        omnid, dp = (counts(fewshot, model, ("fewshot_a",)) for model in ("omnid", "diffusion"))
        if (int(m[1]), int(m[2]), int(m[3]), int(m[4])) != (*omnid, *dp):
            errors.append(f"headline: few-shot {m[1]}/{m[2]} and {m[3]}/{m[4]}; summaries {omnid}, {dp}")
        errors += p_errors("headline: few-shot p", m[5], fisher_exact(*omnid, *dp))
        for model, tuned in (("omnid", omnid), ("diffusion", dp)):
            blind = counts(fewshot, model, ("fewshot_a",), "blind")
            if above(CellResult(*tuned, ()), CellResult(*blind, ())):
                errors.append(f"headline: few-shot {model} {tuned} is above its blind control {blind}")
    return errors


SIX_TASKS_SUMMARY = "six_tasks_cpu2.json"
"""The six-task campaign's summary: docs/results.md's "Six tasks" rebuild command reads it."""
SIX_TASK_METHODS = ("omnid", "diffusion", "act", "vqbet")
SIX_TASK_NAMES = {"OmniD": "omnid", "DP": "diffusion", "ACT": "act", "VQ-BeT": "vqbet"}
SIX_TASK_SENTENCE = (
    r"on `(\w+)` ID (\d+)/(\d+) vs (\d+)/(\d+), (\d+)/(\d+), (\d+)/(\d+)"
    r"(?: \(above their blind controls: ([\w\-, ]+)\))?"
)
"""The headline's six-task sentence (once or more): a task's ID counts of OmniD, DP, ACT and VQ-BeT,
optionally the methods above their blind controls there (exactly those)."""
SIX_TASK_POOLED = (
    r"pooled over (\d) tasks OmniD (\d+)/(\d+) vs DP (\d+)/(\d+) \(p = ([\d.<\s]+)\), "
    r"ACT (\d+)/(\d+), VQ-BeT (\d+)/(\d+)"
)
"""The headline's pooled six-task sentence: tasks, the four methods' ID counts over them, OmniD vs DP's
Mantel-Haenszel p."""


def six_task_errors(readme: str, records: Sequence[EvalRecord]) -> list[str]:
    """The headline's six-task counts against the campaign's summary."""
    errors: list[str] = []
    text = " ".join(headline_section(readme).split())
    cells, blind = collect(records), collect(records, "blind")
    sentences = list(re.finditer(SIX_TASK_SENTENCE, text))
    if not sentences:
        errors.append(f"headline: expected a sentence matching {SIX_TASK_SENTENCE!r}, found none")
    for m in sentences:
        task, stated = m[1], [int(x) for x in m.groups()[1:9]]
        truth = [n for model in SIX_TASK_METHODS for n in astuple(cells[(model, task, "id")])[:2]]
        if stated != truth:
            errors.append(f"headline: six tasks, {task}: stated {stated}, the summary gives {truth}")
        if m[10] is not None:
            named = {SIX_TASK_NAMES.get(name.strip(), name.strip()) for name in m[10].split(",")}
            truly = {
                model
                for model in SIX_TASK_METHODS
                if above(cells[(model, task, "id")], blind[(model, task, "id")])
            }
            if named != truly:
                errors.append(f"headline: on {task} above their blind controls: {named}, truly {truly}")
    if m := claim(text, SIX_TASK_POOLED, errors):
        # Pooled over the tasks every method has been evaluated on (a task in progress is not pooled yet).
        measured = {t for _, t, setting in cells if setting == "id"}
        tasks = sorted(t for t in measured if all((model, t, "id") in cells for model in SIX_TASK_METHODS))
        pooled = [
            sum(astuple(cells[(model, t, "id")])[i] for t in tasks)
            for model in SIX_TASK_METHODS
            for i in (0, 1)
        ]
        stated = [int(x) for x in (m[2], m[3], m[4], m[5], *m.groups()[6:])]
        if (int(m[1]), stated) != (len(tasks), pooled):
            errors.append(f"headline: pooled {m[1]} tasks {stated}; the summary: {len(tasks)} tasks {pooled}")
        strata = [
            (*astuple(cells[("omnid", t, "id")])[:2], *astuple(cells[("diffusion", t, "id")])[:2])
            for t in tasks
        ]
        errors += p_errors("headline: six tasks pooled p", m[6], mantel_haenszel(strata))
    named = re.findall(r"on (`\w+`(?:(?:, | and )`\w+`)*) none is above its blind control", text)
    for task in (task for tasks in named for task in re.findall(r"`(\w+)`", tasks)):
        for model in SIX_TASK_METHODS:
            if above(cells[(model, task, "id")], blind[(model, task, "id")]):
                errors.append(f"headline: on {task} {model} is above its blind control")
    return errors


def test_readme_six_task_counts_match_the_campaign_summary():
    assert_each_edit_is_caught(
        six_task_errors,
        load([SIX_TASKS_SUMMARY]),
        (
            ("ID 25/30 vs 13/30, 7/30, 6/30", "ID 25/30 vs 12/30, 7/30, 6/30"),
            ("on `add_condiment`,", "on `select_apple`,"),  # OmniD, DP and ACT are above theirs there
            ("and `texas_holdem` none", "and `select_apple` none"),  # the list's last task is checked too
            ("OmniD 51/180 vs DP 34/180", "OmniD 51/180 vs DP 33/180"),
            ("(p = 0.026), ACT", "(p = 0.26), ACT"),
            ("vs 2/30, 7/30, 14/30", "vs 2/30, 7/30, 13/30"),  # the second task's sentence is checked too
            ("controls: OmniD, ACT)", "controls: OmniD, ACT, VQ-BeT)"),  # VQ-BeT's blind does as well
            ("controls: OmniD, ACT)", "controls: OmniD)"),
        ),
    )


MULTITASK_SENTENCE = (
    r"one (OmniD|DP) for all (\d) tasks \((\d+) steps\) (\d+)/(\d+) \(blind (\d+)/(\d+)\) "
    r"vs the single-task models' (\d+)/(\d+) \(p = ([\d.<\s]+)\)"
)
"""The headline's multi-task sentence (once per method measured): the one model's ID counts over the
tasks, its blind control's, the single-task models' of its method, and their Mantel-Haenszel p."""
MULTITASK_AGAINST_OMNID = r"behind the one OmniD \(p = ([\d.<\s]+)\)"
"""The headline's comparison of the two multi-task models: Mantel-Haenszel p by task."""
MULTITASK_STEPS = ROOT / "docs" / "six_tasks_steps.json"
"""The single-task budgets; the one model trains for their sum."""


def multitask_errors(readme: str, records: Sequence[EvalRecord]) -> list[str]:
    """The headline's multi-task counts against the campaign's summary."""
    errors: list[str] = []
    text = " ".join(headline_section(readme).split())
    cells, blind = collect(records), collect(records, "blind")
    sentences = list(re.finditer(MULTITASK_SENTENCE, text))
    measured = {
        name for name, model in SIX_TASK_NAMES.items() if any(m == model + "_multitask" for m, *_ in cells)
    }
    for name in sorted(measured - {m[1] for m in sentences}):
        errors.append(f"headline: expected {name}'s sentence matching {MULTITASK_SENTENCE!r}, found none")
    steps = sum(json.loads(MULTITASK_STEPS.read_text()).values())
    for m in sentences:
        single = SIX_TASK_NAMES[m[1]]
        together = single + "_multitask"
        tasks = [t for (model, t, setting) in cells if model == together and setting == "id"]
        truth = [len(tasks), steps]
        for table, model in ((cells, together), (blind, together), (cells, single)):
            truth += [sum(astuple(table[(model, t, "id")])[i] for t in tasks) for i in (0, 1)]
        stated = [int(x) for x in m.groups()[1:9]]
        if stated != truth:
            errors.append(f"headline: {m[1]} for all tasks: stated {stated}, the summary gives {truth}")
        strata = [
            (*astuple(cells[(together, t, "id")])[:2], *astuple(cells[(single, t, "id")])[:2]) for t in tasks
        ]
        errors += p_errors(f"headline: {m[1]} for all tasks p", m[10], mantel_haenszel(strata))
    if m := re.search(MULTITASK_AGAINST_OMNID, text):
        tasks = [t for (model, t, setting) in cells if model == "diffusion_multitask" and setting == "id"]
        strata = [
            (
                *astuple(cells[("omnid_multitask", t, "id")])[:2],
                *astuple(cells[("diffusion_multitask", t, "id")])[:2],
            )
            for t in tasks
        ]
        errors += p_errors("headline: one DP against the one OmniD p", m[1], mantel_haenszel(strata))
    return errors


def test_readme_multitask_counts_match_the_campaign_summary():
    assert_each_edit_is_caught(
        multitask_errors,
        load([SIX_TASKS_SUMMARY]),
        (
            ("78/180 (blind", "79/180 (blind"),
            ("(blind 12/180)", "(blind 9/180)"),
            ("models' 51/180", "models' 34/180"),
            ("51/180 (p = 0.0016)", "51/180 (p = 0.026)"),
            ("(14000 steps)", "(3000 steps)"),
            ("one OmniD for all", "one OmniD for every"),  # OmniD's sentence gone
            ("47/180 (blind", "46/180 (blind"),
            ("(blind 10/180)", "(blind 7/180)"),
            ("models' 34/180 (p = 0.11)", "models' 51/180 (p = 0.11)"),
            ("34/180 (p = 0.11)", "34/180 (p = 0.026)"),
            ("one DP for all", "one DP for every"),  # DP's sentence gone
            ("the one OmniD (p = 0.00024)", "the one OmniD (p = 0.0016)"),
        ),
    )


NEW_CAMERA_SUMMARIES = ("new-camera_seed1000_cpu2.json", "new-camera_seed1001_cpu2.json")
"""The new camera's two-seed test: docs/results.md's "Few-shot on camera A" test rebuild pools these."""
NEW_CAMERA_SENTENCE = (
    r"with 1000 steps OmniD (\d+)/(\d+) vs DP (\d+)/(\d+) on `select_apple` \(p = ([\d.<\s]+)\), "
    r"OmniD above its blind control \((\d+)/(\d+), p = ([\d.]+)\), DP not"
)
"""The headline's new-camera sentence: the selected recipe's (``long``) OmniD and DP counts, their Fisher p,
OmniD's blind control and its p."""
ZERO_SHOT_SENTENCE = r"zero-shot OmniD (\d+)/(\d+), DP (\d+)/(\d+)"


def new_camera_errors(readme: str, records: Sequence[EvalRecord]) -> list[str]:
    """The headline's new-camera counts and claims against the test's summaries."""
    errors: list[str] = []
    text = " ".join(headline_section(readme).split())
    cells, blind = collect(records), collect(records, "blind")
    omnid, dp = (cells[(model, TASK0, "fewshot_a")] for model in ("omnid_long", "diffusion_long"))
    omnid_blind, dp_blind = (blind[(model, TASK0, "fewshot_a")] for model in ("omnid_long", "diffusion_long"))
    if m := claim(text, NEW_CAMERA_SENTENCE, errors):
        stated = [int(m[i]) for i in (1, 2, 3, 4, 6, 7)]
        truth = [*astuple(omnid)[:2], *astuple(dp)[:2], *astuple(omnid_blind)[:2]]
        if stated != truth:
            errors.append(f"headline: new camera, 1000 steps: stated {stated}, the summaries give {truth}")
        errors += p_errors("headline: new camera OmniD - DP p", m[5], fisher_exact(*truth[:4]))
        errors += p_errors("headline: new camera OmniD - blind p", m[8], fisher_exact(*truth[:2], *truth[4:]))
        if not above(omnid, omnid_blind):
            errors.append("headline: new camera, OmniD 1000 steps is not above its blind control")
        if above(dp, dp_blind):
            errors.append("headline: new camera, DP 1000 steps is above its blind control")
    if m := claim(text, ZERO_SHOT_SENTENCE, errors):
        stated = [int(x) for x in m.groups()]
        truth = [
            n
            for model in ("omnid_zero_shot", "diffusion_zero_shot")
            for n in astuple(cells[(model, TASK0, "fewshot_a")])[:2]
        ]
        if stated != truth:
            errors.append(f"headline: zero-shot stated {stated}, the summaries give {truth}")
    return errors


def test_readme_new_camera_counts_match_the_test_summaries():
    assert_each_edit_is_caught(
        new_camera_errors,
        load(NEW_CAMERA_SUMMARIES),
        (
            ("with 1000 steps OmniD 23/60", "with 1000 steps OmniD 24/60"),
            ("OmniD above its blind control (11/60", "OmniD above its blind control (10/60"),
            ("zero-shot OmniD 0/60, DP 1/60", "zero-shot OmniD 1/60, DP 1/60"),
        ),
    )


CALIBRATION_DRAWS_SUMMARY = "calibration_draws_cpu2.json"
"""The many-draw calibration curve: docs/results.md's "Robustness" rebuild command reads it."""
MANY_DRAWS = r"over (\w+) draws a level (\d+), (\d+) and (\d+) of (\d+) at (\d+), (\d+) and (\d+) cm"
"""The headline's many-draw sentence: draws per level, the pooled successes per level, their episodes."""


def many_draw_errors(readme: str, records: Sequence[EvalRecord]) -> list[str]:
    """The headline's many-draw calibration counts against the curve's summary."""
    errors: list[str] = []
    if m := claim(" ".join(headline_section(readme).split()), MANY_DRAWS, errors):
        levels = [float(m[i]) for i in (6, 7, 8)]
        truth = []
        for level in levels:
            cells = [
                r
                for r in records
                if r.tag("condition") == "calibration" and float(r.tag("level") or 0) == level
            ]
            truth.append((len(cells), sum(r.successes for r in cells), sum(r.episodes for r in cells)))
        stated = [(WORDS.get(m[1], 0), int(m[i]), int(m[5])) for i in (2, 3, 4)]
        if stated != truth:
            errors.append(
                f"headline: many draws (draws, successes, episodes) per level {stated}; summary {truth}"
            )
    return errors


def test_readme_many_draw_counts_match_their_summary():
    assert_each_edit_is_caught(
        many_draw_errors,
        read_run_summary(SUMMARIES / CALIBRATION_DRAWS_SUMMARY, robustness.PROTOCOL).evaluations,
        (
            ("79, 77 and 79 of 100", "79, 78 and 79 of 100"),
            ("at 1, 2 and 4 cm", "at 1, 2 and 3 cm"),
        ),
    )


METAWORLD_SUMMARIES = tuple(sorted(p.name for p in SUMMARIES.glob("metaworld_*-v3_cpu2.json")))
"""The MetaWorld comparison, one file per task: docs/results.md's "MetaWorld" rebuild command merges these."""
METAWORLD_SENTENCE = (
    r"MetaWorld\]\([^)]*\) \((\d) of 5 tasks[^)]*\): OmniD (\d+)/(\d+) vs DP (\d+)/(\d+) "
    r"on the same four cameras \(p = ([\d.<\s]+)\), DP on `corner2` alone (\d+)/(\d+) "
    r"\(the published image DP's (\d+(?:\.\d+)?) % "
    r"on another protocol\), OmniD without the hand camera (\d+)/(\d+)"
)
"""The headline's MetaWorld sentence: tasks measured, OmniD's (the first of the comparison's ``BASES``
measured) and DP's (four cameras) counts over them and their p (Fisher for one task, Mantel-Haenszel by task
for several), DP on ``corner2``, the published image DP's mean over the same tasks, OmniD on the fixed
cameras."""
METAWORLD_FIXED = {"omnid_layer2": "omnid_fixed_layer2", "omnid": "omnid_fixed"}
"""Each OmniD of the comparison's ``BASES`` and the same OmniD on the fixed cameras."""


def metaworld_errors(readme: str, records: Sequence[EvalRecord]) -> list[str]:
    """The headline's MetaWorld counts against the per-task summaries."""
    errors: list[str] = []
    if m := claim(" ".join(headline_section(readme).split()), METAWORLD_SENTENCE, errors):
        cells = collect(records)
        tasks = sorted({t for _, t, _ in cells})
        omnid = next(b for b in metaworld_comparison.BASES if (b, tasks[0], "id") in cells)
        models = (omnid, "dp", "dp_corner2", METAWORLD_FIXED[omnid])
        totals = [sum(astuple(cells[(model, t, "id")])[i] for t in tasks) for model in models for i in (0, 1)]
        truth = [len(tasks), *totals]
        stated = [int(m[i]) for i in (1, 2, 3, 4, 5, 7, 8, 10, 11)]
        if stated != truth:
            errors.append(f"headline: MetaWorld stated {stated}, the summaries give {truth}")
        strata = [
            (*astuple(cells[(omnid, t, "id")])[:2], *astuple(cells[("dp", t, "id")])[:2]) for t in tasks
        ]
        p = fisher_exact(*strata[0]) if len(strata) == 1 else mantel_haenszel(strata)
        errors += p_errors("headline: MetaWorld OmniD - DP p", m[6], p)
        published = sum(metaworld_comparison.PUBLISHED[t][1] for t in tasks) / len(tasks)
        if abs(float(m[9]) - published) > 0.05:
            errors.append(
                f"headline: MetaWorld published image DP {m[9]} %, the mean over {tasks} is {published}"
            )
    return errors


METAWORLD_EDITS = (
    ("(3 of 5 tasks", "(2 of 5 tasks"),
    ("OmniD 15/90 vs DP", "OmniD 4/90 vs DP"),  # assembly-v3 and push-v3 alone
    ("vs DP 25/90 on", "vs DP 13/90 on"),  # assembly-v3 and push-v3 alone
    ("four cameras (p = 0.094)", "four cameras (p = 0.035)"),  # their Mantel-Haenszel p
    ("alone 12/90", "alone 13/90"),
    ("image DP's 29.3 %", "image DP's 22.5 %"),  # their published mean
    ("hand camera 15/90", "hand camera 10/90"),  # theirs
)


def test_readme_metaworld_counts_match_the_task_summaries():
    parts = [
        read_run_summary(SUMMARIES / name, metaworld_comparison.PROTOCOL) for name in METAWORLD_SUMMARIES
    ]
    assert parts, "no MetaWorld summary under docs/results/"
    records = merge_run_summaries(parts, METAWORLD_SUMMARIES).evaluations
    assert_each_edit_is_caught(metaworld_errors, records, METAWORLD_EDITS)


@pytest.fixture(scope="module")
def headline_records() -> list[EvalRecord]:
    return load(HEADLINE_SUMMARIES)


@pytest.fixture(scope="module")
def fewshot_records() -> list[EvalRecord]:
    return load(FEWSHOT_SUMMARIES)


def test_readme_headline_matches_the_summaries(headline_records, fewshot_records):
    assert headline_errors(README.read_text(), headline_records, fewshot_records) == []


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("| 74/90 (73-89 %) |", "| 75/90 (73-89 %) |"),  # a count
        ("| 74/90 (73-89 %) |", "| 74/90 (72-89 %) |"),  # an interval
        ("| 50/360 (11-18 %) |", "| 50/350 (11-18 %) |"),  # a denominator
        ("| 2/90 (1-8 %) |", "| |"),  # a blanked cell
        ("**0.021**", "**0.21**"),  # a p-value
        ("fails 89/90 episodes", "fails 88/90 episodes"),
        ("keeps 72/90 with", "keeps 73/90 with"),
        ("at two seeds of three", "at three seeds of three"),
        ("(OmniD 19/90, DP 10/90, p = 0.10;", "(OmniD 19/90, DP 9/90, p = 0.10;"),
        ("DP 10/90, p = 0.10;", "DP 10/90, p = 0.01;"),
        ("Below: three", "Below: two"),
        ("OmniD leads in distribution at each seed", "OmniD leads in distribution at most seeds"),  # gone
        ("| scrambled geometry, ID |", "| scrambled geometry, position OOD |"),  # an unknown column
    ],
)
def test_an_edited_readme_fails(old, new, headline_records, fewshot_records):
    """The checker can fail: each edit of one headline number or claim makes it report an error."""
    readme = README.read_text()
    assert readme.count(old) == 1, f"the README no longer contains {old!r} once: update this edit"
    errors = headline_errors(readme.replace(old, new), headline_records, fewshot_records)
    assert len(errors) == 1, f"editing {old!r} -> {new!r}: expected one error, got {errors}"


@pytest.mark.parametrize(
    "page", [RESULTS_PAGE, HISTORY_PAGE, VALIDATION_PAGE], ids=["results", "history", "validation"]
)
def test_every_interval_on_the_results_pages_is_its_counts_wilson_interval(page):
    found = ON_PAGE.findall(page.read_text())
    assert found, f"{page.name}: no 'k/n (low-high %)' found"
    wrong = []
    for k, n, low, high in found:
        estimate = wilson_interval(int(k), int(n))
        if (printed(estimate.low, low), printed(estimate.high, high)) != (low, high):
            wrong.append(f"{k}/{n} ({low}-{high} %): Wilson gives {estimate.low:.4f}-{estimate.high:.4f}")
    assert wrong == []


def test_an_edited_interval_on_a_results_page_fails():
    """The page check can fail: the same regex and rule reject a wrong interval."""
    (k, n, low, high) = ON_PAGE.findall("OmniD 74/90 (73.1-88.9 %)")[0]
    estimate = wilson_interval(int(k), int(n))
    assert (printed(estimate.low, low), printed(estimate.high, high)) != (low, high)


def anchors(page: Path) -> set[str]:
    """GitHub's heading anchors of a markdown page."""
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)
    headings = re.findall(r"^#+ (.+)$", text, re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in headings}


def link_errors(page: Path, only_into: Sequence[Path] = ()) -> list[str]:
    """Relative links of ``page`` whose file or heading does not exist (only those into ``only_into``)."""
    errors = []
    for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if only_into and file not in only_into:
            continue
        if not file.exists():
            errors.append(f"{page.name}: {target}: no such file")
        elif anchor and file.suffix == ".md" and anchor not in anchors(file):
            errors.append(f"{page.name}: {target}: no such heading in {file.name}")
    return errors


def test_links_of_the_results_pages_resolve():
    pages = [RESULTS_PAGE, HISTORY_PAGE, DIAGNOSTICS_PAGE, VALIDATION_PAGE, SUMMARIES / "README.md"]
    assert [e for page in pages for e in link_errors(page)] == []


def test_links_into_the_results_pages_resolve():
    pages = [README, *(ROOT / "docs").glob("*.md")]
    into = [RESULTS_PAGE, HISTORY_PAGE, DIAGNOSTICS_PAGE, VALIDATION_PAGE]
    assert [e for page in pages for e in link_errors(page, into)] == []


def test_rebuild_commands_name_the_committed_summaries():
    """The results page's rebuild commands (the only places it writes ``docs/results/``: its links are
    relative) pool the files this test checks, and they exist."""
    named = set(re.findall(r"docs/results/([\w.-]+\.json)", RESULTS_PAGE.read_text()))
    committed = {*HEADLINE_SUMMARIES, *FEWSHOT_SUMMARIES, *NEW_CAMERA_SUMMARIES, SIX_TASKS_SUMMARY}
    assert committed <= named
    assert [name for name in named if not (SUMMARIES / name).is_file()] == []


@pytest.mark.parametrize(
    "page",
    [RESULTS_PAGE, HISTORY_PAGE, DIAGNOSTICS_PAGE, VALIDATION_PAGE, SUMMARIES / "README.md"],
    ids=lambda p: p.name,
)
def test_no_path_of_one_machine(page):
    text = page.read_text()
    assert [p for p in MACHINE_PATHS if p in text] == []
