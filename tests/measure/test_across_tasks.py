"""The tables over several tasks: every method beside its controls and per range of env seeds, cells not
above their blind control marked, pooled rows tested by task-stratified Mantel-Haenszel, claims checked
range by range, the per-task heterogeneity."""

from __future__ import annotations

import re

from lerobot_omnid.measure.across_tasks import NOT_ABOVE_BLIND, above, pooled_comparison, task_table
from lerobot_omnid.measure.report import format_p
from lerobot_omnid.measure.results import CellResult, EvalRecord
from lerobot_omnid.measure.stats import fisher_exact, mantel_haenszel

LABELS = {"omnid": "OmniD", "diffusion": "DP"}
TASKS = ("task_a", "task_b")


def record(model, task, successes, seed, control="", setting="id", episodes=15) -> EvalRecord:
    return EvalRecord(
        (model, task, setting), control, 1000, seed, successes, episodes, f"{model}/{task}/{seed}"
    )


def records(omnid_counts, dp_counts, blind=0) -> list[EvalRecord]:
    """Per task and range (eval seeds 1 and 2) OmniD's and DP's successes of 15, and ``blind`` for each
    blind control."""
    rows = []
    for task, per_range in zip(TASKS, omnid_counts, strict=True):
        rows += [record("omnid", task, k, seed) for seed, k in zip((1, 2), per_range, strict=True)]
    for task, per_range in zip(TASKS, dp_counts, strict=True):
        rows += [record("diffusion", task, k, seed) for seed, k in zip((1, 2), per_range, strict=True)]
    for model in ("omnid", "diffusion"):
        rows += [record(model, task, blind, seed, control="blind") for task in TASKS for seed in (1, 2)]
    rows += [record("omnid", task, 2, seed, control="scrambled") for task in TASKS for seed in (1, 2)]
    return rows


def rows_of(table: list[str]) -> dict[tuple[str, str], list[str]]:
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in table[2:]]
    return {(c[0], c[1]): c for c in cells}


def test_above_needs_a_higher_rate_and_a_significant_test():
    assert above(CellResult(10, 15, ()), CellResult(0, 15, ()))
    assert not above(CellResult(3, 15, ()), CellResult(0, 15, ()))  # p = 0.22
    assert not above(CellResult(0, 15, ()), CellResult(10, 15, ()))


def test_task_table_rows_ranges_controls_and_marks():
    rs = records(omnid_counts=[(12, 11), (9, 8)], dp_counts=[(3, 2), (1, 4)], blind=1)
    table = task_table(rs, ("omnid", "diffusion"), TASKS, LABELS, unseen=None)
    assert table[0].split("|")[3:7] == [" id (%) ", " range 1 ", " range 2 ", " blind "]
    rows = rows_of(table)
    omnid_a, dp_a = rows[("task_a", "OmniD")], rows[("task_a", "DP")]
    assert omnid_a[2].startswith("76.7 (") and NOT_ABOVE_BLIND not in omnid_a[2]  # 23/30 against 2/30
    assert dp_a[2].startswith("16.7 (") and dp_a[2].endswith(NOT_ABOVE_BLIND)  # 5/30 against 2/30
    assert omnid_a[3].startswith("12/15") and omnid_a[4].startswith("11/15")
    assert omnid_a[5].startswith("2/30") and omnid_a[6].startswith("4/30")  # blind, scrambled
    assert dp_a[6] == "—"  # DP has no scrambled control
    assert omnid_a[7] == "" and dp_a[7].startswith("+60.0")
    assert dp_a[8] == format_p(fisher_exact(23, 30, 5, 30))
    pooled_dp = rows[("**pooled, 2 tasks**", "DP")]
    assert pooled_dp[2].startswith("16.7 (") and pooled_dp[3].startswith("4/30")
    assert pooled_dp[8] == format_p(mantel_haenszel([(23, 30, 5, 30), (17, 30, 5, 30)]))


def only_row(table: list[str]) -> list[str]:
    (line,) = table[2:]
    return [c.strip() for c in line.strip("|").split("|")]


def test_pooled_comparison_ranges_and_heterogeneity():
    steady = records(omnid_counts=[(12, 11), (9, 10)], dp_counts=[(3, 2), (1, 4)])
    row = only_row(pooled_comparison(steady, ("omnid", "diffusion"), TASKS, LABELS))
    assert row[0] == "DP" and row[1].startswith("+53.3")
    assert all(re.search(r", p [=<] \d", cell) for cell in row[3:5]) and row[5] == "yes"
    assert not any("p = <" in cell for cell in row)  # a small p reads "p < 0.0001"
    assert row[6] == "+60, +47" and row[7].startswith("Q = ") and "1 df" in row[7]
    # The second range alone shows no difference: the claim does not hold in every range.
    split = records(omnid_counts=[(12, 3), (9, 2)], dp_counts=[(3, 2), (1, 4)])
    assert only_row(pooled_comparison(split, ("omnid", "diffusion"), TASKS, LABELS))[5] == "no"


def test_without_a_base_the_table_has_no_difference_columns_and_pooled_marks_are_stratified():
    rs = records(omnid_counts=[(12, 11), (9, 8)], dp_counts=[(3, 2), (1, 4)], blind=1)
    table = task_table(rs, ("omnid", "diffusion"), TASKS, LABELS, base=None, controls=("blind",))
    assert table[0].strip("|").split("|")[-1].strip() == "blind"
    rows = rows_of(table)
    # DP over both tasks: 10/60 against its blind 4/60, stratified p = 0.16: not above it.
    assert rows[("**pooled, 2 tasks**", "DP")][2].endswith(NOT_ABOVE_BLIND)
    assert NOT_ABOVE_BLIND not in rows[("**pooled, 2 tasks**", "OmniD")][2]


def test_an_unseen_table_cell_is_marked_against_the_id_blind_control():
    rs = records(omnid_counts=[(12, 11), (9, 8)], dp_counts=[(3, 2), (1, 4)], blind=1)
    rs += [record("omnid", "task_a", 12, seed, setting="ood2") for seed in (1, 2)]  # 24/30 vs blind 2/30
    rs += [record("diffusion", "task_a", 2, seed, setting="ood2") for seed in (1, 2)]  # 4/30 vs 2/30
    rows = rows_of(task_table(rs, ("omnid", "diffusion"), TASKS, LABELS, unseen="ood2"))
    omnid_ood2, dp_ood2 = rows[("task_a", "OmniD")][7], rows[("task_a", "DP")][7]
    assert omnid_ood2.startswith("80.0 (") and NOT_ABOVE_BLIND not in omnid_ood2
    assert dp_ood2.startswith("13.3 (") and dp_ood2.endswith(NOT_ABOVE_BLIND)
    assert rows[("task_b", "OmniD")][7] == "—"  # not evaluated there
