"""Markdown tables of the benchmark: the paper's layout (section 4), every success rate with its Wilson 95 %
interval, OmniD against each other method with Fisher's exact test, each method against its controls, the
position-shift curve and its area.

Pure functions of their arguments: pooled cells (:func:`lerobot_omnid.measure.results.collect`) or the
evaluation records themselves (:class:`lerobot_omnid.measure.results.EvalRecord`), plus reading the given
open-loop diagnostic files. Rates are printed in %, differences in percentage points (pp).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from lerobot_omnid.measure.results import CellResult, EvalEntry, EvalRecord, Key, collect, train_seeds
from lerobot_omnid.measure.stats import Estimate, fisher_exact, rate_difference, wilson_interval

MISSING = "—"
HOLD_LABEL = "(holding the measured pose)"
Cell = CellResult | None
"""A table cell: a result, or None where nothing was evaluated (yet)."""


def write_markdown(lines: Sequence[str], path: Path) -> None:
    """Write a report's ``lines`` to ``path`` (creating its folder) and print them."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def task_title(task: str) -> str:
    return task.replace("_", " ").title()


def format_rate(cell: CellResult) -> str:
    """``50.0 (23.7-76.3)``: the success rate and its Wilson 95 % interval, in %."""
    interval = cell.interval
    return f"{cell.rate:.1f} ({100 * interval.low:.1f}-{100 * interval.high:.1f})"


def format_counts(cell: CellResult | tuple[int, int] | None) -> str:
    """``5/10 (23.7-76.3 %)``: successes of episodes (a cell, or the pair) and the Wilson 95 % interval;
    :data:`MISSING` for a cell not evaluated (None)."""
    if cell is None:
        return MISSING
    successes, episodes = (cell.successes, cell.episodes) if isinstance(cell, CellResult) else cell
    interval = wilson_interval(successes, episodes)
    return f"{successes}/{episodes} ({100 * interval.low:.1f}-{100 * interval.high:.1f} %)"


def format_difference(estimate: Estimate) -> str:
    """``+20.0 (-20.1 to 52.3)``: a difference of rates and its interval, in percentage points."""
    return f"{100 * estimate.value:+.1f} ({100 * estimate.low:+.1f} to {100 * estimate.high:+.1f})"


def format_p(p: float) -> str:
    """Two significant digits, down to 1e-4."""
    return f"{p:.2g}" if p >= 1e-4 else "<0.0001"


def p_phrase(p: float) -> str:
    """``p = 0.039`` or ``p < 0.0001``, for a p-value inside a sentence or beside other numbers."""
    text = format_p(p)
    return f"p < {text[1:]}" if text.startswith("<") else f"p = {text}"


def short_commit(commit: str | None) -> str:
    """A commit's first 12 hex digits, its ``+dirty`` mark kept; ``?`` when not recorded."""
    if commit is None:
        return "?"
    sha, plus, mark = commit.partition("+")
    return sha[:12] + plus + mark


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return [
        "| " + " | ".join(header) + " |",
        "|" + "|".join(" --- " for _ in header) + "|",
        *("| " + " | ".join(row) + " |" for row in rows),
    ]


def _rows(labels: Sequence[str], cells: Sequence[Sequence[Cell]]) -> list[list[str]]:
    """Formatted rows; the highest rate of each column is bold (ties included) where at least two rows have
    a result and they differ, as the paper does."""
    best = []
    for column in zip(*cells, strict=True):
        rates = [c.rate for c in column if isinstance(c, CellResult)]
        best.append(max(rates) if len(rates) >= 2 and min(rates) < max(rates) else None)
    rows = []
    for label, row in zip(labels, cells, strict=True):
        text = [label]
        for c, top in zip(row, best, strict=True):
            if isinstance(c, CellResult):
                text.append(f"**{format_rate(c)}**" if c.rate == top else format_rate(c))
            else:
                text.append(MISSING)
        rows.append(text)
    return rows


def pooled(cells: Iterable[CellResult]) -> CellResult | None:
    """The cells' counts added up (None if there are none)."""
    cells = list(cells)
    if not cells:
        return None
    return CellResult(
        sum(c.successes for c in cells),
        sum(c.episodes for c in cells),
        tuple(s for c in cells for s in c.sources),
    )


def id_table(
    results: Mapping[Key, CellResult], methods: Sequence[str], tasks: Sequence[str], labels: Mapping[str, str]
) -> list[str]:
    """Success (%) per task in the ID setting, cameras B-E, with the average: the episodes of every task
    pooled (the mean of the tasks' rates when each has as many episodes). An average over fewer tasks than
    the table has (some not evaluated yet) is marked with *."""
    cells, averages = [], []
    for m in methods:
        row = [results.get((m, t, "id")) for t in tasks]
        cells.append(row)
        present = [c for c in row if c is not None]
        average = pooled(present)
        averages.append(
            MISSING if average is None else format_rate(average) + ("*" if len(present) < len(tasks) else "")
        )
    rows = _rows([labels.get(m, m) for m in methods], cells)
    return markdown_table(
        ["Method", *(task_title(t) for t in tasks), "Average"],
        [[*r, a] for r, a in zip(rows, averages, strict=True)],
    )


def generalisation_table(
    results: Mapping[Key, CellResult],
    methods: Sequence[str],
    task0: str,
    task1: str,
    backgrounds: Sequence[str],
    labels: Mapping[str, str],
) -> list[str]:
    """Task 0: ID, position OOD, each background OOD, fine-tuned on camera A for task 0 and for task 1."""
    keys = [
        (task0, "id"),
        (task0, "position_ood"),
        *((task0, b) for b in backgrounds),
        (task0, "fewshot_a"),
        (task1, "fewshot_a"),
    ]
    cells = [[results.get((m, t, s)) for t, s in keys] for m in methods]
    header = ["Method", "Task 0 ID", "Position OOD", *(f"Background {b}" for b in backgrounds)]
    header += ["Fine-tune Task 0-A", "Fine-tune Task 1-A"]
    return markdown_table(header, _rows([labels.get(m, m) for m in methods], cells))


ABLATION_ROWS = ("ResNet-18", "ResNet-101", "OFG module", "Multi-view input fusion")
ABLATION_COLUMNS = (  # title, model, which of ABLATION_ROWS it has
    ("ResNet-101", "omnid_resnet101", (False, True, True, True)),
    ("w/o OFG", "omnid_no_ofg", (True, False, False, True)),
    ("Camera A", "omnid_cam_a", (True, False, True, False)),
    ("Base model", "omnid", (True, False, True, True)),
)


def ablation_table(results: Mapping[Key, CellResult], task0: str) -> list[str]:
    """OmniD's ablation on task 0 (ID): which components each column has, and its success (%)."""
    rows = [
        [name, *("✓" if parts[i] else "" for _, _, parts in ABLATION_COLUMNS)]
        for i, name in enumerate(ABLATION_ROWS)
    ]
    success = [
        format_rate(results[key]) if (key := (m, task0, "id")) in results else MISSING
        for _, m, _ in ABLATION_COLUMNS
    ]
    return markdown_table(
        ["", *(title for title, _, _ in ABLATION_COLUMNS)], [*rows, ["**Success rate (%)**", *success]]
    )


def comparison_table(
    records: Sequence[EvalRecord],
    base: str,
    others: Sequence[str],
    cells: Sequence[tuple[str, str]],
    labels: Mapping[str, str],
) -> list[str]:
    """``base`` (OmniD) against each of ``others`` in each (task, setting) both were evaluated in: counts
    with Wilson intervals, the difference with Newcombe's interval and the two-sided Fisher p-value of the
    episodes pooled over training seeds; with more than one training seed, the p-value of each too."""
    seeds = train_seeds(records)
    per_seed = len(seeds) > 1
    results = collect(records)
    by_seed = {s: collect(records, train_seed=s) for s in seeds} if per_seed else {}
    rows = []
    for other in others:
        for task, setting in cells:
            a, b = results.get((base, task, setting)), results.get((other, task, setting))
            if a is None or b is None:
                continue
            row = [task, setting, labels.get(other, other), format_counts(a), format_counts(b)]
            row += [format_difference(rate_difference(a.successes, a.episodes, b.successes, b.episodes))]
            row += [format_p(fisher_exact(a.successes, a.episodes, b.successes, b.episodes))]
            if per_seed:
                row.append(", ".join(f"{s}: {_p(by_seed[s], base, other, task, setting)}" for s in seeds))
            rows.append(row)
    header = [
        "Task",
        "Setting",
        "Against",
        labels.get(base, base),
        "Other",
        f"{labels.get(base, base)} - other (pp)",
    ]
    header += ["Fisher p (pooled)"] + (["Fisher p per training seed"] if per_seed else [])
    return markdown_table(header, rows)


def _p(results: Mapping[Key, CellResult], base: str, other: str, task: str, setting: str) -> str:
    a, b = results.get((base, task, setting)), results.get((other, task, setting))
    if a is None or b is None:
        return MISSING
    return format_p(fisher_exact(a.successes, a.episodes, b.successes, b.episodes))


def controls_table(
    records: Sequence[EvalRecord],
    methods: Sequence[str],
    task: str,
    settings: Sequence[str],
    control_of: Mapping[tuple[str, str], str],
    labels: Mapping[str, str],
    control_labels: Mapping[str, str],
) -> list[str]:
    """Each method against its own controls (the same checkpoint, see ``methods.control_flags``) on ``task``:
    the margin of the checkpoint as trained over the control with Newcombe's interval, and the two-sided
    Fisher p-value. ``control_of[(setting, control)]`` is the setting whose control evaluation controls
    ``setting`` (the blind control of a background OOD is the ID one's)."""
    trained = collect(records)
    rows = []
    for control, control_label in control_labels.items():
        controlled = collect(records, control=control)
        for m in methods:
            for setting in settings:
                a = trained.get((m, task, setting))
                source = control_of.get((setting, control))
                b = controlled.get((m, task, source)) if source else None
                if a is None or b is None:
                    continue
                where = setting if source == setting else f"{setting} (control of {source})"
                row = [labels.get(m, m), control_label, where, format_counts(a), format_counts(b)]
                row += [format_difference(rate_difference(a.successes, a.episodes, b.successes, b.episodes))]
                rows.append([*row, format_p(fisher_exact(a.successes, a.episodes, b.successes, b.episodes))])
    header = ["Method", "Control", "Setting", "As trained", "Control", "Margin (pp)", "Fisher p"]
    return markdown_table(header, rows)


def curve_area(
    results: Mapping[Key, CellResult], model: str, task: str, bands: Mapping[str, tuple[float, float]]
) -> tuple[float, CellResult | None] | None:
    """Area under the success-vs-distance curve, normalised by the bands' extent: the width-weighted mean of
    the band rates (%). Returns (area, pooled counts) where every band was evaluated, the pooled counts being
    the area's own when every band has the same width and episodes (its interval and test then hold for the
    area), else None; None if a band is missing."""
    cells = [results.get((model, task, band)) for band in bands]
    if any(c is None for c in cells):
        return None
    widths = [high - low for low, high in bands.values()]
    area = sum(w * c.rate for w, c in zip(widths, cells, strict=True)) / sum(widths)
    uniform = len({round(w, 9) for w in widths}) == 1 and len({c.episodes for c in cells}) == 1
    return area, pooled(cells) if uniform else None


def curve_table(
    results: Mapping[Key, CellResult],
    methods: Sequence[str],
    task: str,
    bands: Mapping[str, tuple[float, float]],
    labels: Mapping[str, str],
) -> list[str]:
    """Success (%) per position band (distance outside the training square, cm) and the curve's area."""
    cells = [[results.get((m, task, band)) for band in bands] for m in methods]
    rows = _rows([labels.get(m, m) for m in methods], cells)
    for m, row in zip(methods, rows, strict=True):
        area = curve_area(results, m, task, bands)
        if area is None:
            row.append(MISSING)
        else:
            row.append(format_rate(area[1]) if area[1] is not None else f"{area[0]:.1f}")
    header = ["Method", *(f"{low:g}-{high:g} cm" for low, high in bands.values()), "Area (mean over 0-10 cm)"]
    return markdown_table(header, rows)


def offline_table(
    paths: Mapping[Key, Path],
    methods: Sequence[str],
    task0: str,
    settings: Sequence[str],
    labels: Mapping[str, str],
) -> list[str]:
    """Task 0: mean open-loop TCP position error (cm) / gripper error on held-out expert episodes per setting,
    from ``omnid-offline-eval``'s JSON files (``paths``, keyed by cell). The lowest position error is bold.
    A last row gives, for scale, the error of holding the measured pose (the same for every method)."""
    rows = []
    holds: dict[str, dict] = {}  # per setting, from the first method that has it
    for m in methods:
        row = [labels.get(m, m)]
        for setting in settings:
            path = paths.get((m, task0, setting))
            if path is None or not path.is_file():
                row.append(MISSING)
                continue
            result = json.loads(path.read_text())
            row.append(f"{result['position_cm']:.1f} / {result['gripper']:.2f}")
            if "hold" in result:
                holds.setdefault(setting, result["hold"])
        rows.append(row)
    reference = [HOLD_LABEL] + [
        f"{h['position_cm']:.1f} / {h['gripper']:.2f}" if (h := holds.get(s)) else MISSING for s in settings
    ]
    for c in range(1, len(settings) + 1):
        errors = [float(r[c].split(" / ")[0]) for r in rows if r[c] != MISSING]
        if len(errors) >= 2 and min(errors) < max(errors):
            for r in rows:
                if r[c] != MISSING and float(r[c].split(" / ")[0]) == min(errors):
                    r[c] = f"**{r[c]}**"
    return markdown_table(["Method", *settings], [*rows, reference])


def raw_table(
    entries: Sequence[EvalEntry], records: Sequence[EvalRecord], labels: Mapping[str, str]
) -> list[str]:
    """One row per evaluation: every record (this folder's, resumed and merged ones) with its counts,
    interval, commit and source, then the planned evaluations no record holds (same cell, control and seeds)
    yet."""
    rows = []
    for r in sorted(records, key=lambda r: (r.key, r.control, r.train_seed or 0, r.eval_seed or 0)):
        model, task, setting = r.key
        counts = format_counts(CellResult(r.successes, r.episodes, (r.source,)))
        seeds = [r.control, str(r.train_seed), str(r.eval_seed)]
        rows.append(
            [labels.get(model, model), task, setting, *seeds, counts, short_commit(r.commit), f"`{r.source}`"]
        )
    done = {(r.key, r.control, r.train_seed, r.eval_seed) for r in records}
    for e in entries:
        if (e.key, e.control, e.train_seed, e.seed) not in done:
            model, task, setting = e.key
            seeds = [e.control, str(e.train_seed), str(e.seed)]
            rows.append([labels.get(model, model), task, setting, *seeds, MISSING, "", "not run yet"])
    header = [
        "Model",
        "Task",
        "Setting",
        "Control",
        "Training seed",
        "Eval seed",
        "Successes",
        "Commit",
        "Source",
    ]
    return markdown_table(header, rows)
