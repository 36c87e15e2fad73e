"""Tables of a comparison over several tasks: every method on every task beside its own controls, each
range of test env seeds beside their pool, and OmniD against each method pooled over the tasks with the
per-task heterogeneity.

Pure functions of evaluation records (:class:`lerobot_omnid.measure.results.EvalRecord`). A *range* is
one eval seed: ``lerobot-eval --seed=1000k`` runs consecutive env seeds, one draw of layouts; a claim is
reported as holding in every range only if it does in each on its own. A cell counts as *above its blind
control* when its rate is higher and a two-sided test puts the difference at p < 0.05 (Fisher's for one
task, Mantel-Haenszel's stratified by task for several).

Pooled over tasks, a difference is that of the summed counts: with the same episodes per task and method
(the benchmark's design) it is the mean of the per-task differences, which is also the Mantel-Haenszel
estimate of the common difference; its p-value is the Mantel-Haenszel test's, stratified by task.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from lerobot_omnid.measure.report import (
    MISSING,
    format_counts,
    format_difference,
    format_p,
    format_rate,
    markdown_table,
    p_phrase,
    pooled,
)
from lerobot_omnid.measure.results import CellResult, EvalRecord, Key, collect
from lerobot_omnid.measure.stats import fisher_exact, heterogeneity, mantel_haenszel, rate_difference

ALPHA = 0.05
NOT_ABOVE_BLIND = "†"
"""Mark of a cell whose success is not above its blind control's."""


def eval_seeds(records: Sequence[EvalRecord]) -> list[int]:
    """The eval seeds (ranges of env seeds) found in ``records``, sorted."""
    return sorted({r.eval_seed for r in records if r.eval_seed is not None})


def above(cell: CellResult, control: CellResult) -> bool:
    """Whether ``cell`` succeeds more often than ``control``, with Fisher's p < :data:`ALPHA`."""
    p = fisher_exact(cell.successes, cell.episodes, control.successes, control.episodes)
    return cell.rate > control.rate and p < ALPHA


def _in_range(records: Sequence[EvalRecord], seed: int) -> list[EvalRecord]:
    return [r for r in records if r.eval_seed == seed]


def _strata(
    cells: Mapping[Key, CellResult], a: str, b: str, tasks: Sequence[str], setting: str
) -> list[tuple[int, int, int, int]]:
    """Per task where both ``a`` and ``b`` were evaluated: (successes of a, episodes, of b, episodes)."""
    strata = []
    for task in tasks:
        x, y = cells.get((a, task, setting)), cells.get((b, task, setting))
        if x is not None and y is not None:
            strata.append((x.successes, x.episodes, y.successes, y.episodes))
    return strata


def _paired(
    cells: Mapping[Key, CellResult],
    controlled: Mapping[Key, CellResult],
    method: str,
    task: str,
    setting: str,
    control_setting: str | None = None,
) -> list[tuple[int, int, int, int]]:
    """``[(successes, episodes, control's successes, control's episodes)]`` of ``method`` on ``task`` in
    ``setting`` (the control's in ``control_setting``, default the same), or ``[]`` where either is
    missing."""
    a = cells.get((method, task, setting))
    b = controlled.get((method, task, control_setting or setting))
    return [(a.successes, a.episodes, b.successes, b.episodes)] if a and b else []


def _rate_or_missing(cell: CellResult | None) -> str:
    return MISSING if cell is None else format_rate(cell)


def _marked(cell: CellResult | None, blind: list[tuple[int, int, int, int]]) -> str:
    """The rate, marked :data:`NOT_ABOVE_BLIND` where its blind control is there and not beaten: ``blind``
    holds per task the cell's counts and its control's (successes, episodes, successes, episodes)."""
    if cell is None:
        return MISSING
    if not blind:
        return format_rate(cell)
    if len(blind) == 1:
        s1, n1, s2, n2 = blind[0]
        beaten = above(CellResult(s1, n1, ()), CellResult(s2, n2, ()))
    else:  # several tasks: more successes, and the Mantel-Haenszel test stratified by task
        more = sum(s1 / n1 - s2 / n2 for s1, n1, s2, n2 in blind) > 0
        beaten = more and mantel_haenszel(blind) < ALPHA
    return format_rate(cell) + ("" if beaten else f" {NOT_ABOVE_BLIND}")


def task_table(
    records: Sequence[EvalRecord],
    methods: Sequence[str],
    tasks: Sequence[str],
    labels: Mapping[str, str],
    base: str | None = "omnid",
    setting: str = "id",
    unseen: str | None = None,
    controls: Sequence[str] = ("blind", "scrambled"),
) -> list[str]:
    """One row per task and method: success (%) in ``setting`` pooled over the ranges and in each range,
    each control of the checkpoint (same setting), the ``unseen`` setting (e.g. an unseen table), and the
    difference to ``base`` with its Fisher p (no such columns for ``base=None``); then one row per method
    pooled over the tasks, whose p is the Mantel-Haenszel test stratified by task. Success not above its
    blind control is marked, in ``unseen`` too (against the blind control in ``setting``)."""
    seeds = eval_seeds(records)
    cells = collect(records)
    by_range = {k: collect(_in_range(records, k)) for k in seeds}
    by_control = {c: collect(records, control=c) for c in controls}
    rows = []

    def row(label: str, method: str, pick: Sequence[str]) -> list[str]:
        def total(table: Mapping[Key, CellResult], where: str = setting) -> CellResult | None:
            return pooled(c for t in pick if (c := table.get((method, t, where))) is not None)

        cell = total(cells)
        controlled = by_control.get("blind", {})
        blind = [counts for t in pick for counts in _paired(cells, controlled, method, t, setting)]
        text = [label, labels.get(method, method), _marked(cell, blind)]
        text += [format_counts(total(by_range[k])) for k in seeds]
        text += [format_counts(total(by_control[k])) for k in controls]
        if unseen is not None:
            # Its blind control is the ID one: the same env seeds, and a blind policy sees no table.
            unseen_blind = [c for t in pick for c in _paired(cells, controlled, method, t, unseen, setting)]
            text.append(_marked(total(cells, unseen), unseen_blind))
        if base is None:
            return text
        strata = _strata(cells, base, method, pick, setting)  # the tasks both were evaluated on
        if method == base or not strata:
            return [*text, "", ""]
        a = pooled(CellResult(s1, n1, ()) for s1, n1, _, _ in strata)
        b = pooled(CellResult(s2, n2, ()) for _, _, s2, n2 in strata)
        difference = rate_difference(a.successes, a.episodes, b.successes, b.episodes)
        p = fisher_exact(*strata[0]) if len(pick) == 1 else mantel_haenszel(strata)
        return [*text, format_difference(difference), format_p(p)]

    for task in tasks:
        rows += [row(task, m, (task,)) for m in methods]
    if len(tasks) > 1:
        # Pooled over the tasks each method was evaluated on; fewer than all of them is marked with *.
        for m in methods:
            done = sum(cells.get((m, t, setting)) is not None for t in tasks)
            rows.append(row(f"**pooled, {done} tasks**" + ("*" if done < len(tasks) else ""), m, tasks))
    header = ["Task", "Method", f"{setting} (%)", *(f"range {k}" for k in seeds), *controls]
    header += [unseen] if unseen is not None else []
    header += [] if base is None else [f"{labels.get(base, base)} - method (pp)", "p"]
    return markdown_table(header, rows)


def pooled_comparison(
    records: Sequence[EvalRecord],
    methods: Sequence[str],
    tasks: Sequence[str],
    labels: Mapping[str, str],
    base: str = "omnid",
    setting: str = "id",
) -> list[str]:
    """``base`` against each method over the tasks: the pooled difference and its Mantel-Haenszel p, the
    same in each range on its own, whether the claim holds in every range (same sign, p < :data:`ALPHA` in
    each), the per-task differences and their heterogeneity (Cochran's Q, I^2)."""
    seeds = eval_seeds(records)
    cells = collect(records)
    by_range = {k: collect(_in_range(records, k)) for k in seeds}
    rows = []
    for method in methods:
        if method == base:
            continue
        strata = _strata(cells, base, method, tasks, setting)
        if not strata:
            continue
        a = pooled(CellResult(s1, n1, ()) for s1, n1, _, _ in strata)
        b = pooled(CellResult(s2, n2, ()) for _, _, s2, n2 in strata)
        difference = rate_difference(a.successes, a.episodes, b.successes, b.episodes)
        text = [labels.get(method, method), format_difference(difference)]
        text.append(format_p(mantel_haenszel(strata)))
        holds = difference.value != 0
        for k in seeds:
            ranged = _strata(by_range[k], base, method, tasks, setting)
            if not ranged:
                text.append(MISSING)
                holds = False
                continue
            d = sum(s1 / n1 - s2 / n2 for s1, n1, s2, n2 in ranged) / len(ranged)
            p = mantel_haenszel(ranged)
            holds = holds and p < ALPHA and d * difference.value > 0
            text.append(f"{100 * d:+.1f}, {p_phrase(p)}")
        text.append("yes" if holds else "no")
        text.append(", ".join(f"{100 * (s1 / n1 - s2 / n2):+.0f}" for s1, n1, s2, n2 in strata))
        if len(strata) > 1:
            h = heterogeneity(strata)
            text.append(f"Q = {h.q:.1f} ({h.df} df), {p_phrase(h.p)}, I² = {100 * h.i2:.0f} %")
        else:
            text.append(MISSING)
        rows.append(text)
    base_label = labels.get(base, base)
    header = ["Against", f"{base_label} - method, pooled (pp)", "p (stratified by task)"]
    header += [f"range {k}: mean per-task difference (pp), p" for k in seeds]
    header += ["Holds in every range", "Per task (pp)", "Heterogeneity"]
    return markdown_table(header, rows)
