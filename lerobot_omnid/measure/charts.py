"""The benchmark's PNG charts, every success rate with its Wilson 95 % interval: grouped bars of the tables,
and the position-shift curve (success against the object's distance outside the training square)."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

from lerobot_omnid.measure.report import ABLATION_COLUMNS, task_title
from lerobot_omnid.measure.results import CellResult, Key


def pyplot() -> ModuleType:
    """matplotlib's pyplot with the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: Path) -> Path:
    """Lay out a pyplot figure, write it as a PNG to ``path`` (folders made), close it; returns ``path``."""
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    pyplot().close(fig)
    return path


def error_bars(cells: Sequence[CellResult]) -> list[list[float]]:
    """(2, N) distances (%) from each rate down and up to the ends of its Wilson interval."""
    return [
        [c.rate - 100 * c.interval.low for c in cells],
        [100 * c.interval.high - c.rate for c in cells],
    ]


Group = tuple[str, str, str]
"""A bar group: its x label, task and setting."""
Panel = tuple[str, list[Group], list[str]]
"""A bar panel: its title, its groups and its series (models)."""


def bar_panels(
    results: Mapping[Key, CellResult],
    models: Sequence[str],
    tasks: Sequence[str],
    task0: str,
    task1: str,
    backgrounds: Sequence[str],
) -> list[Panel]:
    """The grouped panels of the bar chart: ID per task; task-0 generalisation and few-shot. Each keeps
    only the groups some model has a result in and the models with a result in one of them; a panel with
    nothing left is dropped, so a profile's chart shows what it measured and no empty axes."""
    panels: list[Panel] = [
        ("ID success, cameras B-E", [(task_title(t), t, "id") for t in tasks], list(models)),
        (
            f"{task_title(task0)}: generalisation and few-shot on camera A",
            [("ID", task0, "id"), ("Pos. OOD", task0, "position_ood")]
            + [(f"BG {b}", task0, b) for b in backgrounds]
            + [("FT 0-A", task0, "fewshot_a"), ("FT 1-A", task1, "fewshot_a")],
            list(models),
        ),
    ]
    kept: list[Panel] = []
    for title, groups, rows in panels:
        groups = [g for g in groups if any((m, g[1], g[2]) in results for m in rows)]
        rows = [m for m in rows if any((m, t, s) in results for _, t, s in groups)]
        if groups:
            kept.append((title, groups, rows))
    return kept


def ablation_bars(results: Mapping[Key, CellResult], task0: str) -> list[tuple[str, str]]:
    """(column title, model) of the ablation's models with a task-0 ID result, or none when fewer than two
    of them have one (one bar compares nothing)."""
    found = [(title, model) for title, model, _ in ABLATION_COLUMNS if (model, task0, "id") in results]
    return found if len(found) > 1 else []


def draw_panel(ax: Any, panel: Panel, results: Mapping[Key, CellResult], labels: Mapping[str, str]) -> None:
    """One :data:`Panel` on the axes ``ax``: per group a bar for each model with a result, with its Wilson
    interval, x positions 0, 1, ... by group; the legend outside on the right."""
    title, groups, rows = panel
    width = 0.8 / max(len(rows), 1)
    for i, m in enumerate(rows):
        found = [(g, results[(m, t, s)]) for g, (_, t, s) in enumerate(groups) if (m, t, s) in results]
        xs = [g + (i - (len(rows) - 1) / 2) * width for g, _ in found]
        cells = [c for _, c in found]
        ax.bar(xs, [c.rate for c in cells], width, yerr=error_bars(cells), capsize=2, label=labels.get(m, m))
    ax.set_xticks(range(len(groups)), [textwrap.fill(name, 16) for name, _, _ in groups])
    ax.set(title=title, ylabel="success (%)", ylim=(0, 105))
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")


def bar_chart(
    results: Mapping[Key, CellResult],
    models: Sequence[str],
    tasks: Sequence[str],
    task0: str,
    task1: str,
    backgrounds: Sequence[str],
    labels: Mapping[str, str],
    path: Path,
) -> Path:
    """Grouped bars of success (%) with Wilson intervals: the :func:`bar_panels`, then the ablation."""
    plt = pyplot()
    panels = bar_panels(results, models, tasks, task0, task1, backgrounds)
    ablation = ablation_bars(results, task0)
    n_axes = max(len(panels) + bool(ablation), 1)
    fig, axes = plt.subplots(n_axes, 1, figsize=(11, 3.2 * n_axes), squeeze=False)
    axes = axes[:, 0]
    for ax, panel in zip(axes, panels, strict=False):
        draw_panel(ax, panel, results, labels)
    if ablation:
        ax = axes[-1]
        cells = [results[(m, task0, "id")] for _, m in ablation]
        ax.bar(range(len(ablation)), [c.rate for c in cells], 0.5, yerr=error_bars(cells), capsize=2)
        ax.set_xticks(range(len(ablation)), [title for title, _ in ablation])
        ax.set(title=f"OmniD ablation, {task_title(task0)} ID", ylabel="success (%)", ylim=(0, 105))
    return save_figure(fig, path)


def position_curve_chart(
    results: Mapping[Key, CellResult],
    methods: Sequence[str],
    task: str,
    bands: Mapping[str, tuple[float, float]],
    labels: Mapping[str, str],
    path: Path,
) -> Path:
    """Success (%) against the distance outside the training square (each band at its middle, cm), one
    line per method with its Wilson intervals; the band edges are drawn as grid lines."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    offsets = {
        m: (i - (len(methods) - 1) / 2) * 0.12 for i, m in enumerate(methods)
    }  # cm, so bars do not hide
    for m in methods:
        found = [
            ((low + high) / 2, results[(m, task, b)])
            for b, (low, high) in bands.items()
            if (m, task, b) in results
        ]
        if not found:
            continue
        xs = [x + offsets[m] for x, _ in found]
        cells = [c for _, c in found]
        ax.errorbar(
            xs,
            [c.rate for c in cells],
            yerr=error_bars(cells),
            marker="o",
            capsize=3,
            label=labels.get(m, m),
        )
    edges = sorted({edge for band in bands.values() for edge in band})
    ax.set_xticks(edges)
    ax.grid(axis="x", alpha=0.4)
    ax.set(
        title=f"{task_title(task)}: success against distance outside the training square",
        xlabel="distance outside the 10 cm training square, L-inf (cm)",
        ylabel="success (%)",
        ylim=(-2, 105),
        xlim=(edges[0], edges[-1]),
    )
    ax.legend(fontsize="small")
    return save_figure(fig, path)
