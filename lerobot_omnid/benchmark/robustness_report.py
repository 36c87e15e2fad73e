"""``omnid-robustness``'s tables and charts from success counts per cell (pure but for writing the PNG).

A checkpoint's rows pool its cells: a perturbation level over its draws, a dead-camera variant per camera
and over the cameras ("any one"), each over the eval seeds it ran on. Every rate comes with its Wilson 95 %
interval, its share of the rate as trained and a two-sided Fisher test against it, as trained counted on
the same eval seeds as the row (so a second eval seed of as trained and the controls alone does not mix
env seeds into the curves' shares); the blind and scrambled-geometry controls are rows of the table and
horizontal bands of the chart.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lerobot_omnid.benchmark.robustness_plan import CONTROLS, DEAD, LABELS, Cell
from lerobot_omnid.measure.across_tasks import above
from lerobot_omnid.measure.charts import error_bars, pyplot, save_figure
from lerobot_omnid.measure.results import CellResult
from lerobot_omnid.measure.stats import equal_rates, fisher_exact, rate_difference

ANY_CAMERA = "any one"
"""The perturbation column of a dead-camera variant pooled over its cameras."""
CURVES = ("calibration", "bumped")
BAND_COLOURS = {"nominal": "tab:green", "blind": "tab:gray", "scrambled": "tab:orange"}
SERIES_COLOURS = {
    "calibration": "tab:blue",
    "bumped": "tab:purple",
    "dead_removed": "tab:blue",
    "dead_black": "tab:red",
    "dead_black_mid": "tab:purple",
}
SERIES_SHIFT = 0.06  # fraction of the spacing between x positions that series are shifted by, so bars show
TARGET_LEVEL = 1.0  # robustness targets: the calibration error (cm and degrees) at which ...
TARGET_CALIBRATION_SHARE = 80.0  # ... at least this share (%) of the rate as trained is kept
TARGET_DEAD_SHARE = 50.0  # and with one camera dead, at least this share


Counts = tuple[int, int]
"""(successes, episodes) of one evaluation."""


@dataclass(frozen=True)
class Row:
    """One line of a checkpoint's table: ``condition`` (a key of ``LABELS``) at ``level`` (curves) or for
    ``camera`` (dead cameras; ``ANY_CAMERA`` pooled), the pooled ``result``, its ``parts`` (per draw or
    per camera: name, successes, episodes) and ``as_trained``, the rate as trained on the same eval seeds
    (None for as trained itself or where it has none of them)."""

    condition: str
    result: CellResult
    level: float | None = None
    camera: str = ""
    parts: tuple[tuple[str, int, int], ...] = ()
    as_trained: CellResult | None = None

    @property
    def perturbation(self) -> str:
        if self.level is not None:
            return f"{self.level:g} cm, {self.level:g} deg" if self.level else "none"
        return self.camera or "-"

    @property
    def key(self) -> tuple[str, str]:
        return self.condition, self.perturbation


def _sum(counts: Sequence[Counts]) -> Counts:
    return sum(k for k, _ in counts), sum(n for _, n in counts)


def _pool(parts: Sequence[tuple[str, int, int]]) -> CellResult:
    return CellResult(*_sum([(k, n) for _, k, n in parts]), ())


def table_rows(counts: Mapping[Cell, Mapping[int, Counts]]) -> list[Row]:
    """The rows of one checkpoint from its counts per cell and eval seed, each pooled over its eval seeds,
    in the order as trained, calibration error and bumped cameras by level, dead cameras, controls; cells
    without counts are left out."""
    nominal = counts.get(Cell("nominal"), {})
    pooled = {cell: _sum(list(by_seed.values())) for cell, by_seed in counts.items()}

    def row(condition: str, cells: Sequence[Cell], result: CellResult, **fields: Any) -> Row:
        seeds = {k for c in cells for k in counts[c] if k in nominal}
        as_trained = CellResult(*_sum([nominal[k] for k in sorted(seeds)]), ()) if seeds else None
        return Row(condition, result, as_trained=as_trained, **fields)

    rows = []
    if nominal:
        rows.append(Row("nominal", CellResult(*pooled[Cell("nominal")], ()), level=0.0))
    for condition in CURVES:
        levels = sorted({c.level for c in counts if c.condition == condition})
        for level in levels:
            cells = [c for c in counts if c.condition == condition and c.level == level]
            cells.sort(key=lambda c: c.draw)
            parts = tuple((f"draw {c.draw}", *pooled[c]) for c in cells)
            rows.append(row(condition, cells, _pool(parts), level=level, parts=parts))
    for condition in DEAD:
        cells = sorted((c for c in counts if c.condition == condition), key=lambda c: c.camera)
        rows += [row(condition, [c], CellResult(*pooled[c], ()), camera=c.camera) for c in cells]
        if len(cells) > 1:
            parts = tuple((c.camera, *pooled[c]) for c in cells)
            rows.append(row(condition, cells, _pool(parts), camera=ANY_CAMERA, parts=parts))
    controls = [Cell(c) for c in CONTROLS if Cell(c) in counts]
    rows += [row(c.condition, [c], CellResult(*pooled[c], ())) for c in controls]
    return rows


def _rate(result: CellResult) -> str:
    return f"{result.rate:.0f} ({100 * result.interval.low:.0f}-{100 * result.interval.high:.0f})"


def _versus(row: CellResult, other: CellResult) -> str:
    """``row`` against ``other``: difference (pp) with Newcombe's interval, Fisher p."""
    d = rate_difference(row.successes, row.episodes, other.successes, other.episodes)
    p = fisher_exact(row.successes, row.episodes, other.successes, other.episodes)
    return f"{100 * d.value:+.0f} pp ({100 * d.low:+.0f} to {100 * d.high:+.0f}), p = {p:.2g}"


def _as_trained(row: Row, nominal: Row) -> CellResult:
    """The rate as trained that ``row`` is compared with: on its eval seeds, else every seed's."""
    return row.as_trained or nominal.result


def target_lines(rows: Sequence[Row]) -> list[str]:
    """The robustness targets for one checkpoint: the share of its rate as trained kept at 1 cm / 1 degree of
    calibration error (at least 80 %) and with one camera dead, per variant pooled over the cameras (at
    least 50 %; the worst camera beside it); counted only where the checkpoint is significantly above its
    blind control."""
    found = {r.key: r for r in rows}
    nominal = next((r for r in rows if r.condition == "nominal"), None)
    blind = next((r for r in rows if r.condition == "blind"), None)
    if nominal is None or not nominal.result.successes:
        return []
    if blind is None or blind.as_trained is None:
        counted = "not counted: no blind control"
    elif above(blind.as_trained, blind.result):
        counted = "counted: significantly above its blind control"
    else:
        counted = "not counted: not significantly above its blind control"
    lines = [f"Robustness targets ({counted}):", ""]

    def share(row: Row) -> float:
        reference = _as_trained(row, nominal)
        return 100 * row.result.rate / reference.rate if reference.successes else 0.0

    def verdict(row: Row, target: float) -> str:
        kept = share(row)
        met = "met" if kept >= target else f"missed by {target - kept:.0f} points"
        reference = _as_trained(row, nominal)
        counts = (
            f"{row.result.successes}/{row.result.episodes} against {reference.successes}/{reference.episodes}"
        )
        return f"{kept:.0f} % of as trained ({counts}; target >= {target:.0f} %): {met}"

    calibration = next((r for r in rows if r.condition == "calibration" and r.level == TARGET_LEVEL), None)
    if calibration is not None:
        kept = verdict(calibration, TARGET_CALIBRATION_SHARE)
        lines.append(f"- {LABELS['calibration']} at {calibration.perturbation}: {kept}")
    for condition in DEAD:
        cameras = [r for r in rows if r.condition == condition and r.camera != ANY_CAMERA]
        if not cameras:
            continue
        pooled = found.get((condition, ANY_CAMERA), cameras[0])
        worst = min(cameras, key=lambda r: r.result.rate)
        lines.append(
            f"- {LABELS[condition]}, {pooled.camera}: {verdict(pooled, TARGET_DEAD_SHARE)}; worst camera "
            f"{worst.camera} {share(worst):.0f} %"
        )
    return [*lines, ""] if len(lines) > 2 else []


def draw_spread_lines(rows: Sequence[Row]) -> list[str]:
    """Per curve level with several draws: the worst and best draw, the median draw, and whether the
    draws differ more than chance would make them (:func:`equal_rates`): one draw is one sample of a
    calibration error, so a level's pooled rate hides how much the direction of the error matters."""
    lines = []
    for row in rows:
        if row.condition not in CURVES or len(row.parts) < 2:
            continue
        ordered = sorted(row.parts, key=lambda part: part[1] / part[2])
        worst, best, median = ordered[0], ordered[-1], ordered[(len(ordered) - 1) // 2]
        test = equal_rates([(k, n) for _, k, n in row.parts])
        lines.append(
            f"- {LABELS[row.condition]} at {row.perturbation}, {len(row.parts)} draws: worst {worst[0]} "
            f"{worst[1]}/{worst[2]}, median {median[1]}/{median[2]}, best {best[0]} {best[1]}/{best[2]}; "
            f"equal rates across draws: chi2 = {test.chi2:.1f} (df {test.df}), permutation p = {test.p:.2g}"
        )
    return ["Spread across draws:", "", *lines, ""] if lines else []


def checkpoint_lines(label: str, description: str, rows: Sequence[Row], chart: str | None) -> list[str]:
    """A checkpoint's section of the report: its use of the cameras (as trained against its controls), the
    issue's targets, the table, the chart."""
    lines = [f"## {label}", "", description, ""]
    found = {r.condition: r for r in rows if r.condition in ("nominal", *CONTROLS)}
    nominal = found.get("nominal")
    if nominal is None:
        return [*lines, "No evaluation as trained yet.", ""]
    for control in CONTROLS:
        if control in found:
            a, b = _as_trained(found[control], nominal), found[control].result
            verdict = "significantly above" if above(a, b) else "not significantly above"
            lines.append(f"- as trained against its {LABELS[control]}: {_versus(a, b)}: {verdict} it.")
    if "blind" in found:
        lines += [
            "",
            "A curve counts only for a checkpoint significantly above its blind control.",
        ]
    lines += ["", *target_lines(rows)]
    lines += [
        "| Condition | Perturbation | Successes | Success % (Wilson 95 %) | "
        "Share of as trained (same seeds) | Against as trained (same seeds) | Per draw / camera |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in rows:
        r = row.result
        reference = _as_trained(row, nominal)
        share = f"{100 * r.rate / reference.rate:.0f} %" if reference.successes else "n/a"
        against = "" if row.condition == "nominal" else _versus(r, reference)
        parts = ", ".join(f"{name} {k}/{n}" for name, k, n in row.parts)
        lines.append(
            f"| {LABELS[row.condition]} | {row.perturbation} | {r.successes}/{r.episodes} | {_rate(r)} | "
            f"{share} | {against} | {parts} |"
        )
    spread = draw_spread_lines(rows)
    if spread:
        lines += ["", *spread]
    if chart:
        lines += ["", f"![{label}: success against perturbation]({chart})"]
    return [*lines, ""]


def pooled_rows(rows: Sequence[Row]) -> list[Row]:
    """``rows`` without the per-camera rows of a dead-camera variant that has a pooled row."""
    pooled = {r.condition for r in rows if r.camera == ANY_CAMERA}
    return [r for r in rows if r.condition not in pooled or r.camera == ANY_CAMERA]


def comparison_lines(rows_by_label: Mapping[str, Sequence[Row]]) -> list[str]:
    """One table of the pooled rows with a column per checkpoint: success % (Wilson 95 %) and counts."""
    labels = list(rows_by_label)
    keys: list[tuple[str, str]] = []
    for rows in rows_by_label.values():
        keys += [r.key for r in pooled_rows(rows) if r.key not in keys]
    cells = {label: {r.key: r.result for r in rows} for label, rows in rows_by_label.items()}
    lines = [
        "| Condition | Perturbation | " + " | ".join(labels) + " |",
        "| --- | --- |" + " --- |" * len(labels),
    ]
    for condition, perturbation in keys:
        values = []
        for label in labels:
            r = cells[label].get((condition, perturbation))
            values.append(f"{_rate(r)}, {r.successes}/{r.episodes}" if r else "-")
        lines.append(f"| {LABELS[condition]} | {perturbation} | " + " | ".join(values) + " |")
    return lines


def between_lines(rows_by_label: Mapping[str, Sequence[Row]]) -> list[str]:
    """Every pair of checkpoints (in the given order) on each pooled row both have: the difference of
    their rates with Newcombe's interval and a two-sided Fisher test; empty for fewer than two."""
    labels = list(rows_by_label)
    pairs = [(a, b) for i, a in enumerate(labels) for b in labels[i + 1 :]]
    cells = {label: {r.key: r.result for r in pooled_rows(rows)} for label, rows in rows_by_label.items()}
    keys = [
        k
        for k in dict.fromkeys(k for c in cells.values() for k in c)
        if sum(k in c for c in cells.values()) > 1
    ]
    if not pairs or not keys:
        return []
    lines = [
        "| Condition | Perturbation | " + " | ".join(f"{a} - {b}" for a, b in pairs) + " |",
        "| --- | --- |" + " --- |" * len(pairs),
    ]
    for key in keys:
        values = [
            _versus(cells[a][key], cells[b][key]) if key in cells[a] and key in cells[b] else "-"
            for a, b in pairs
        ]
        lines.append(f"| {LABELS[key[0]]} | {key[1]} | " + " | ".join(values) + " |")
    return lines


def rows_json(rows: Sequence[Row]) -> list[dict[str, Any]]:
    return [
        {
            "condition": r.condition,
            "level": r.level,
            "camera": r.camera,
            "successes": r.result.successes,
            "episodes": r.result.episodes,
            "success_rate": r.result.rate,
            "wilson_95": [100 * r.result.interval.low, 100 * r.result.interval.high],
            "parts": [list(p) for p in r.parts],
            "as_trained_same_seeds": (
                [r.as_trained.successes, r.as_trained.episodes] if r.as_trained else None
            ),
        }
        for r in rows
    ]


def rows_from_json(items: Sequence[Mapping[str, Any]]) -> list[Row]:
    """The rows of :func:`rows_json`'s output, so that a committed ``results.json`` rebuilds the report."""
    return [
        Row(
            item["condition"],
            CellResult(item["successes"], item["episodes"], ()),
            level=item["level"],
            camera=item["camera"],
            parts=tuple((name, k, n) for name, k, n in item["parts"]),
            as_trained=CellResult(*item["as_trained_same_seeds"], ())
            if item["as_trained_same_seeds"]
            else None,
        )
        for item in items
    ]


def _plot_series(
    ax: Any, x: Sequence[float], points: Sequence[Row], colour: str, label: str, joined: bool
) -> None:
    """The rates of ``points`` at ``x`` with their Wilson intervals as error bars, joined by a line or not."""
    ax.errorbar(
        x,
        [r.result.rate for r in points],
        yerr=error_bars([r.result for r in points]),
        marker="o",
        capsize=3,
        color=colour,
        label=label,
        **({} if joined else {"ls": "none"}),
    )


def robustness_chart(label: str, rows: Sequence[Row], path: Path) -> Path:
    """Success (%) with Wilson intervals against the perturbation level (calibration error, bumped cameras;
    level 0: as trained) and per dead camera, beside the controls (and, for the dead cameras, the rate as
    trained) as horizontal bands: the rate and its interval."""
    plt = pyplot()
    fig, (ax_curve, ax_dead) = plt.subplots(1, 2, figsize=(12, 4.2), width_ratios=(1.1, 1))
    nominal = next((r for r in rows if r.condition == "nominal"), None)
    controls = [r for r in rows if r.condition in CONTROLS]

    def bands(ax: Any, with_nominal: bool) -> None:
        for r in [*controls, *([nominal] if with_nominal and nominal else [])]:
            colour = BAND_COLOURS[r.condition]
            low, high = 100 * r.result.interval.low, 100 * r.result.interval.high
            ax.axhspan(low, high, color=colour, alpha=0.15, lw=0)
            ax.axhline(r.result.rate, color=colour, ls="--", lw=1, label=f"{LABELS[r.condition]}")

    levels = sorted({r.level for r in rows if r.level is not None})
    span = (max(levels) - min(levels)) if len(levels) > 1 else 1.0
    curves = [c for c in CURVES if any(r.condition == c for r in rows)]
    for i, condition in enumerate(curves):
        points = [r for r in rows if r.condition == condition]
        points = sorted([*([nominal] if nominal else []), *points], key=lambda r: r.level)
        shift = (i - (len(curves) - 1) / 2) * SERIES_SHIFT * span
        x = [r.level + shift for r in points]
        _plot_series(ax_curve, x, points, SERIES_COLOURS[condition], LABELS[condition], joined=True)
    bands(ax_curve, with_nominal=False)
    ax_curve.set_xticks(levels)
    ax_curve.set(
        title=f"{label}: cameras off by L cm and L degrees",
        xlabel="L (cm of translation and degrees of rotation, every camera)",
        ylabel="success (%)",
        ylim=(-2, 105),
    )
    ax_curve.legend(fontsize="small")

    dead = [c for c in DEAD if any(r.condition == c for r in rows)]
    cameras = list(dict.fromkeys(r.camera for r in rows if r.condition in DEAD))
    for i, condition in enumerate(dead):
        points = [r for r in rows if r.condition == condition]
        shift = (i - (len(dead) - 1) / 2) * 3 * SERIES_SHIFT
        x = [cameras.index(r.camera) + shift for r in points]
        _plot_series(ax_dead, x, points, SERIES_COLOURS[condition], LABELS[condition], joined=False)
    bands(ax_dead, with_nominal=True)
    ax_dead.set_xticks(range(len(cameras)), cameras)
    ax_dead.set(
        title=f"{label}: one camera dead",
        xlabel="dead camera",
        ylabel="success (%)",
        ylim=(-2, 105),
        xlim=(-0.5, max(len(cameras), 1) - 0.5),
    )
    ax_dead.legend(fontsize="small")
    return save_figure(fig, path)


def comparison_chart(rows_by_label: Mapping[str, Sequence[Row]], path: Path) -> Path:
    """The checkpoints side by side: success (%) with Wilson intervals against L for the calibration error
    and for the bumped cameras (L = 0: as trained), and per dead-camera variant pooled over the cameras,
    each checkpoint's blind control as a dotted line of its colour (and, for the dead cameras, its rate as
    trained dashed)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), width_ratios=(1, 1, 0.9))
    labels = list(rows_by_label)
    colours = {label: f"C{i}" for i, label in enumerate(labels)}
    for ax, condition in zip(axes, CURVES, strict=False):
        for i, (label, rows) in enumerate(rows_by_label.items()):
            points = sorted(
                (r for r in rows if r.condition in (condition, "nominal")), key=lambda r: r.level or 0.0
            )
            if len(points) < 2:
                continue  # this checkpoint has no such curve (e.g. DP has no calibration)
            shift = (i - (len(labels) - 1) / 2) * SERIES_SHIFT * max(r.level or 0.0 for r in points)
            _plot_series(ax, [(r.level or 0.0) + shift for r in points], points, colours[label], label, True)
        ax.set(title=LABELS[condition], xlabel="L (cm and degrees, every camera)", ylabel="success (%)")
    ax_dead = axes[2]
    for i, (label, rows) in enumerate(rows_by_label.items()):
        points = [r for r in pooled_rows(rows) if r.condition in DEAD and r.camera == ANY_CAMERA]
        shift = (i - (len(labels) - 1) / 2) * 3 * SERIES_SHIFT
        x = [DEAD.index(r.condition) + shift for r in points]
        _plot_series(ax_dead, x, points, colours[label], label, joined=False)
        nominal = next((r for r in rows if r.condition == "nominal"), None)
        if nominal is not None:
            ax_dead.axhline(nominal.result.rate, color=colours[label], ls="--", lw=1)
    ax_dead.set_xticks(range(len(DEAD)), ["removed", "black", "black mid-episode"])
    ax_dead.set(title="one camera dead (any one, pooled)", xlabel="variant", ylabel="success (%)")
    for ax in axes:
        for label, rows in rows_by_label.items():
            blind = next((r for r in rows if r.condition == "blind"), None)
            if blind is not None:
                ax.axhline(blind.result.rate, color=colours[label], ls=":", lw=1.2)
        ax.set_ylim(-2, 105)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize="small", title="dotted: blind control", title_fontsize="x-small")
    return save_figure(fig, path)
