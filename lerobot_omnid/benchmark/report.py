"""Tables laid out like the paper's (section 4) and a bar chart, from ``lerobot-eval``'s ``eval_info.json``.

Pure functions of their arguments (plus reading the given files): an evaluation is a :class:`EvalEntry`
(which table cell it belongs to, which seed, where its ``eval_info.json`` is); entries of one cell (several
eval seeds) are pooled: success rate = successful episodes / episodes over all of them.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

Key = tuple[str, str, str]
"""(model, task, setting): a table cell. model: a method, an ablation or a method whose fine-tuned model
the cell holds; setting: "id", "position_ood", "ood1".."ood4" or "fewshot_a"."""

MISSING = "—"
HOLD_LABEL = "(holding the measured pose)"
NOT_APPLICABLE = "n/a"


@dataclass(frozen=True)
class EvalEntry:
    key: Key
    seed: int | None
    path: Path  # an eval_info.json, which may not exist yet


@dataclass(frozen=True)
class CellResult:
    successes: float  # successful episodes, over every seed of the cell
    episodes: int
    paths: tuple[Path, ...]

    @property
    def rate(self) -> float:
        return 100.0 * self.successes / self.episodes


def read_eval_info(path: Path) -> tuple[float, int]:
    """(success rate in %, episodes) of one ``lerobot-eval`` run."""
    overall = json.loads(Path(path).read_text())["overall"]
    return float(overall["pc_success"]), int(overall["n_episodes"])


def collect(entries: Iterable[EvalEntry]) -> dict[Key, CellResult]:
    """Pool the entries whose ``eval_info.json`` exists, per cell."""
    cells: dict[Key, CellResult] = {}
    for entry in entries:
        if not entry.path.is_file():
            continue
        rate, n = read_eval_info(entry.path)
        old = cells.get(entry.key, CellResult(0.0, 0, ()))
        cells[entry.key] = CellResult(
            old.successes + rate * n / 100.0, old.episodes + n, (*old.paths, entry.path)
        )
    return cells


def task_title(task: str) -> str:
    return task.replace("_", " ").title()


def _fmt(results: Mapping[Key, CellResult], key: Key, not_applicable: set[Key]) -> str:
    if key in not_applicable:
        return NOT_APPLICABLE
    return f"{results[key].rate:.1f}" if key in results else MISSING


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return [
        "| " + " | ".join(header) + " |",
        "|" + "|".join(" --- " for _ in header) + "|",
        *("| " + " | ".join(row) + " |" for row in rows),
    ]


def _bold_best(rows: list[list[str]], columns: Iterable[int]) -> None:
    """Bold the highest number of each column (ties included), as the paper does."""
    for c in columns:
        values = [float(r[c]) for r in rows if r[c] not in (MISSING, NOT_APPLICABLE) and "/" not in r[c]]
        if len(values) < 2 or min(values) == max(values):
            continue
        for r in rows:
            if r[c] not in (MISSING, NOT_APPLICABLE) and "/" not in r[c] and float(r[c]) == max(values):
                r[c] = f"**{r[c]}**"


def id_table(
    results: Mapping[Key, CellResult], methods: Sequence[str], tasks: Sequence[str], labels: Mapping[str, str]
) -> list[str]:
    """Success (%) per task in the ID setting, cameras B-E, with the average over tasks. An average over
    fewer tasks than the table has (some not evaluated yet) is marked with *."""
    rows = []
    for m in methods:
        cells = [_fmt(results, (m, t, "id"), set()) for t in tasks]
        rates = [results[(m, t, "id")].rate for t in tasks if (m, t, "id") in results]
        average = f"{sum(rates) / len(rates):.1f}" if rates else MISSING
        if rates and len(rates) < len(tasks):
            average += "*"
        rows.append([labels.get(m, m), *cells, average])
    _bold_best(rows, range(1, len(tasks) + 1))
    return _table(["Method", *(task_title(t) for t in tasks), "Average"], rows)


def generalisation_table(
    results: Mapping[Key, CellResult],
    methods: Sequence[str],
    task0: str,
    task1: str,
    backgrounds: Sequence[str],
    not_applicable: set[Key],
    labels: Mapping[str, str],
) -> list[str]:
    """Task 0: ID, position OOD, background OODs (one cell, 1/2/3/4), fine-tuned on camera A for task 0
    and for task 1."""
    rows = []
    for m in methods:
        background = "/".join(
            f"{results[(m, task0, b)].rate:.0f}" if (m, task0, b) in results else MISSING for b in backgrounds
        )
        rows.append(
            [
                labels.get(m, m),
                _fmt(results, (m, task0, "id"), not_applicable),
                _fmt(results, (m, task0, "position_ood"), not_applicable),
                background,
                _fmt(results, (m, task0, "fewshot_a"), not_applicable),
                _fmt(results, (m, task1, "fewshot_a"), not_applicable),
            ]
        )
    _bold_best(rows, (1, 2, 4, 5))
    header = [
        "Method",
        "Task 0 ID",
        "Position OOD",
        f"Background OOD ({'/'.join(backgrounds)})",
        "Fine-tune Task 0-A",
        "Fine-tune Task 1-A",
    ]
    return _table(header, rows)


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
        "**Success rate (%)**",
        *(_fmt(results, (m, task0, "id"), set()) for _, m, _ in ABLATION_COLUMNS),
    ]
    return _table(["", *(title for title, _, _ in ABLATION_COLUMNS)], [*rows, success])


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
    return _table(["Method", *settings], [*rows, reference])


def raw_table(entries: Sequence[EvalEntry], labels: Mapping[str, str]) -> list[str]:
    """One row per evaluation run: its cell, seed, result and eval_info.json (or that it is missing)."""
    rows = []
    for e in entries:
        model, task, setting = e.key
        if e.path.is_file():
            rate, n = read_eval_info(e.path)
            rows.append(
                [labels.get(model, model), task, setting, str(e.seed), str(n), f"{rate:.1f}", f"`{e.path}`"]
            )
        else:
            rows.append([labels.get(model, model), task, setting, str(e.seed), "", MISSING, "not run yet"])
    return _table(
        ["Model", "Task", "Setting", "Eval seed", "Episodes", "Success (%)", "eval_info.json"], rows
    )


def bar_chart(
    results: Mapping[Key, CellResult],
    methods: Sequence[str],
    tasks: Sequence[str],
    task0: str,
    task1: str,
    backgrounds: Sequence[str],
    labels: Mapping[str, str],
    path: Path,
) -> Path:
    """Grouped bars of success (%): ID per task; task-0 generalisation; ablation. Written as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [
        ("ID success, cameras B-E", [(task_title(t), t, "id") for t in tasks], methods),
        (
            f"{task_title(task0)}: generalisation and few-shot on camera A",
            [("ID", task0, "id"), ("Pos. OOD", task0, "position_ood")]
            + [(f"BG {b}", task0, b) for b in backgrounds]
            + [("FT 0-A", task0, "fewshot_a"), ("FT 1-A", task1, "fewshot_a")],
            methods,
        ),
    ]
    ablation = [(title, model) for title, model, _ in ABLATION_COLUMNS if (model, task0, "id") in results]
    n_axes = len(panels) + bool(ablation)
    fig, axes = plt.subplots(n_axes, 1, figsize=(11, 3.2 * n_axes), squeeze=False)
    axes = axes[:, 0]
    for ax, (title, groups, rows) in zip(axes, panels, strict=False):
        width = 0.8 / max(len(rows), 1)
        for i, m in enumerate(rows):
            xs = [
                g + (i - (len(rows) - 1) / 2) * width
                for g, (_, t, s) in enumerate(groups)
                if (m, t, s) in results
            ]
            ys = [results[(m, t, s)].rate for _, t, s in groups if (m, t, s) in results]
            ax.bar(xs, ys, width, label=labels.get(m, m))
        ax.set_xticks(range(len(groups)), [name for name, _, _ in groups])
        ax.set(title=title, ylabel="success (%)", ylim=(0, 105))
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
    if ablation:
        ax = axes[-1]
        ax.bar(range(len(ablation)), [results[(m, task0, "id")].rate for _, m in ablation], 0.5)
        ax.set_xticks(range(len(ablation)), [title for title, _ in ablation])
        ax.set(title=f"OmniD ablation, {task_title(task0)} ID", ylabel="success (%)", ylim=(0, 105))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
