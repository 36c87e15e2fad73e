"""A report's tables and charts from finished evaluations: seeds pooled, the paper's layout, OmniD against
the other methods and against each control (Wilson intervals, Newcombe margins, Fisher tests), the
position-shift curve and its area, the open-loop error."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lerobot_omnid.benchmark.methods import CONTROL_LABELS, CONTROLS
from lerobot_omnid.benchmark.outputs import BANDS_CM
from lerobot_omnid.benchmark.plan import BANDS, LABELS, SETTINGS, TASK0, TASK1, TRAIN_SEED, control_setting
from lerobot_omnid.measure.charts import ablation_bars, bar_chart, bar_panels, position_curve_chart
from lerobot_omnid.measure.report import (
    ablation_table,
    comparison_table,
    controls_table,
    curve_area,
    curve_table,
    generalisation_table,
    id_table,
    offline_table,
    raw_table,
)
from lerobot_omnid.measure.results import EvalEntry, EvalRecord, collect, record_of
from lerobot_omnid.measure.stats import fisher_exact


def _write_eval(path: Path, rate: float, n: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"overall": {"pc_success": rate, "n_episodes": n}, "per_task": []}))
    return path


def _records(tmp_path, rows) -> list[EvalRecord]:
    """Finished evaluations' records: rows of (key, eval seed, rate %, episodes[, training seed, control])."""
    records = []
    for i, (key, seed, rate, n, *rest) in enumerate(rows):
        train_seed, control = (rest + [TRAIN_SEED, ""][len(rest) :])[:2]
        path = _write_eval(tmp_path / f"{i}" / "eval_info.json", rate, n)
        records.append(record_of(EvalEntry(key, seed, path, train_seed, control)))
    return records


def test_report_tables_pool_seeds_and_match_the_paper_layout(tmp_path):
    records = _records(
        tmp_path,
        [
            (("omnid", TASK0, "id"), 1, 40.0, 5),
            (("omnid", TASK0, "id"), 2, 60.0, 5),
            (("omnid", TASK1, "id"), 1, 100.0, 10),
            (("diffusion", TASK0, "id"), 1, 80.0, 10),
            *((("omnid", TASK0, f"ood{i}"), 1, 10.0 * i, 10) for i in (1, 2, 4)),
            (("omnid", TASK1, "fewshot_a"), 1, 30.0, 10),
            (("omnid_no_ofg", TASK0, "id"), 1, 20.0, 10),
            (("omnid", TASK0, "id"), 1, 0.0, 10, TRAIN_SEED, "blind"),  # not pooled with the trained model
        ],
    )
    results = collect(records)
    assert results[("omnid", TASK0, "id")].episodes == 10 and results[("omnid", TASK0, "id")].rate == 50.0
    assert collect(records, control="blind")[("omnid", TASK0, "id")].successes == 0
    table = id_table(results, ("omnid", "diffusion"), (TASK0, TASK1), LABELS)
    assert table[0] == "| Method | Select Apple | Select Chemistry Tube | Average |"
    # a lone value is not bold; the average pools the tasks' episodes (15/20)
    assert table[2] == "| OmniD | 50.0 (23.7-76.3) | 100.0 (72.2-100.0) | 75.0 (53.1-88.8) |"
    assert (
        table[3] == "| DP | **80.0 (49.0-94.3)** | — | 80.0 (49.0-94.3)* |"
    )  # average of the evaluated tasks
    table = generalisation_table(
        results, ("omnid", "diffusion"), TASK0, TASK1, ("ood1", "ood2", "ood3", "ood4"), LABELS
    )
    assert table[0] == (
        "| Method | Task 0 ID | Position OOD | Background ood1 | Background ood2 | Background ood3 | "
        "Background ood4 | Fine-tune Task 0-A | Fine-tune Task 1-A |"
    )
    assert table[2] == (
        "| OmniD | 50.0 (23.7-76.3) | — | 10.0 (1.8-40.4) | 20.0 (5.7-51.0) | — | 40.0 (16.8-68.7) | — | "
        "30.0 (10.8-60.3) |"
    )
    assert table[3] == "| DP | **80.0 (49.0-94.3)** | — | — | — | — | — | — | — |"
    table = ablation_table(results, TASK0)
    assert table[0] == "|  | ResNet-101 | w/o OFG | Camera A | Base model |"
    assert table[2] == "| ResNet-18 |  | ✓ | ✓ | ✓ |" and table[4] == "| OFG module | ✓ |  | ✓ | ✓ |"
    assert table[-1] == "| **Success rate (%)** | — | 20.0 (5.7-51.0) | — | 50.0 (23.7-76.3) |"
    missing = EvalEntry(("diffusion", TASK1, "id"), 1, tmp_path / "missing.json", TRAIN_SEED)
    raw = "\n".join(raw_table([missing], records, LABELS))
    assert "| DP | select_chemistry_tube | id |  | 1000 | 1 | — |  | not run yet |" in raw
    blind = (
        f"| OmniD | select_apple | id | blind | 1000 | 1 | 0/10 (0.0-27.8 %) | ? | `{records[-1].source}` |"
    )
    assert blind in raw
    png = bar_chart(
        results,
        ("omnid", "diffusion"),
        (TASK0, TASK1),
        TASK0,
        TASK1,
        ("ood1", "ood2", "ood3", "ood4"),
        LABELS,
        tmp_path / "chart" / "b.png",
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bar_panels_show_what_was_measured_and_no_empty_axes(tmp_path):
    """Groups no model has a result in, models with no result in a panel, a panel with nothing left and an
    ablation of one model are left out; a multi-task model passed among the models gets its bars."""
    records = _records(
        tmp_path,
        [
            (("omnid", TASK0, "id"), 1, 50.0, 10),
            (("omnid", TASK1, "id"), 1, 10.0, 10),
            (("omnid_multitask", TASK0, "id"), 1, 40.0, 10),
            (("diffusion", TASK1, "id"), 1, 20.0, 10),
            (("diffusion", TASK0, "ood2"), 1, 30.0, 10),
        ],
    )
    results = collect(records)
    models = ("omnid", "omnid_multitask", "diffusion", "act")
    oods = ("ood1", "ood2")
    panels = bar_panels(results, models, (TASK0, TASK1), TASK0, TASK1, oods)
    assert panels == [
        (
            "ID success, cameras B-E",
            [("Select Apple", TASK0, "id"), ("Select Chemistry Tube", TASK1, "id")],
            ["omnid", "omnid_multitask", "diffusion"],
        ),
        (
            "Select Apple: generalisation and few-shot on camera A",
            [("ID", TASK0, "id"), ("BG ood2", TASK0, "ood2")],
            ["omnid", "omnid_multitask", "diffusion"],
        ),
    ]
    only_id = collect([r for r in records if r.key[2] == "id" and r.key[1] == TASK1])
    assert [title for title, _, _ in bar_panels(only_id, models, (TASK0, TASK1), TASK0, TASK1, oods)] == [
        "ID success, cameras B-E"
    ]
    assert ablation_bars(results, TASK0) == []  # the base model alone
    with_ablation = collect(
        [*records, *_records(tmp_path / "a", [(("omnid_no_ofg", TASK0, "id"), 1, 0.0, 10)])]
    )
    assert [model for _, model in ablation_bars(with_ablation, TASK0)] == ["omnid_no_ofg", "omnid"]
    png = bar_chart(with_ablation, models, (TASK0, TASK1), TASK0, TASK1, oods, LABELS, tmp_path / "b.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_comparison_pools_training_seeds_and_tests_each(tmp_path):
    """OmniD vs DP with Fisher's test on the episodes pooled over training seeds, and per seed."""
    records = _records(
        tmp_path,
        [
            (("omnid", TASK0, "id"), 1, 60.0, 10, 1000),
            (("omnid", TASK0, "id"), 1, 60.0, 10, 1001),
            (("diffusion", TASK0, "id"), 1, 0.0, 10, 1000),
            (("diffusion", TASK0, "id"), 1, 0.0, 10, 1001),
            (("omnid", TASK0, "ood1"), 1, 50.0, 10, 1000),  # DP not evaluated there: no row
        ],
    )
    table = comparison_table(records, "omnid", ["diffusion"], [(TASK0, "id"), (TASK0, "ood1")], LABELS)
    assert table[0].endswith("| Fisher p (pooled) | Fisher p per training seed |")
    assert len(table) == 3  # header, rule, one row
    # 12/20 vs 0/20 pooled; 6/10 vs 0/10 per seed
    p_pooled, p_seed = fisher_exact(12, 20, 0, 20), fisher_exact(6, 10, 0, 10)
    assert p_pooled < 1e-4 and p_seed == pytest.approx(0.0108, abs=1e-4)
    assert table[2] == (
        "| select_apple | id | DP | 12/20 (38.7-78.1 %) | 0/20 (0.0-16.1 %) | +60.0 (+33.3 to +78.1) | "
        f"<0.0001 | 1000: {p_seed:.2g}, 1001: {p_seed:.2g} |"
    )
    single = [r for r in records if r.train_seed == 1000]
    assert (
        "per training seed"
        not in comparison_table(single, "omnid", ["diffusion"], [(TASK0, "id")], LABELS)[0]
    )


def test_controls_table_margins_over_each_control(tmp_path):
    records = _records(
        tmp_path,
        [
            (("omnid", TASK0, "id"), 1, 70.0, 10),
            (("omnid", TASK0, "ood2"), 1, 30.0, 10),
            (("omnid", TASK0, "id"), 1, 0.0, 10, TRAIN_SEED, "blind"),
            (("omnid", TASK0, "id"), 1, 20.0, 10, TRAIN_SEED, "scrambled"),
            (("diffusion", TASK0, "id"), 1, 50.0, 10),
            (("diffusion", TASK0, "id"), 1, 30.0, 10, TRAIN_SEED, "blind"),
        ],
    )
    control_of = {(s, c): control_setting(s, c, ("id",)) for s in SETTINGS for c in CONTROLS}
    assert control_of[("ood2", "blind")] == "id" and control_of[("ood2", "scrambled")] is None
    assert control_of[("position_ood", "blind")] is None
    table = controls_table(
        records, ("omnid", "diffusion"), TASK0, SETTINGS, control_of, LABELS, CONTROL_LABELS
    )
    assert table[0] == "| Method | Control | Setting | As trained | Control | Margin (pp) | Fisher p |"
    assert (
        table[2]
        == "| OmniD | blind | id | 7/10 (39.7-89.2 %) | 0/10 (0.0-27.8 %) | +70.0 (+28.9 to +89.2) | 0.0031 |"
    )
    assert table[3].startswith(
        "| OmniD | blind | ood2 (control of id) | 3/10 (10.8-60.3 %) | 0/10 (0.0-27.8 %) |"
    )
    assert table[4].startswith("| DP | blind | id | 5/10 (23.7-76.3 %) | 3/10 (10.8-60.3 %) | +20.0 (")
    assert table[5].startswith("| OmniD | scrambled geometry | id | 7/10 (39.7-89.2 %) | 2/10 (5.7-51.0 %) |")
    assert len(table) == 6  # DP has no scrambled control, OmniD's scrambled none in ood2


def test_position_curve_table_area_and_chart(tmp_path):
    bands = BANDS_CM
    assert bands == {
        "position_band_1": (0.0, 2.5),
        "position_band_2": (2.5, 5.0),
        "position_band_3": (5.0, 7.5),
        "position_band_4": (7.5, 10.0),
    }
    records = _records(
        tmp_path,
        [
            *(
                (("omnid", TASK0, band), 1, rate, 10)
                for band, rate in zip(BANDS, (80.0, 60.0, 40.0, 20.0), strict=True)
            ),
            *(
                (("diffusion", TASK0, band), 1, rate, 10)
                for band, rate in zip(BANDS, (40.0, 10.0, 0.0, 0.0), strict=True)
            ),
            (("act", TASK0, "position_band_1"), 1, 50.0, 10),
        ],
    )
    results = collect(records)
    area, counts = curve_area(results, "omnid", TASK0, bands)
    assert area == pytest.approx(50.0) and (counts.successes, counts.episodes) == (20, 40)
    assert curve_area(results, "act", TASK0, bands) is None  # bands missing
    table = curve_table(results, ("omnid", "diffusion", "act"), TASK0, bands, LABELS)
    assert table[0] == "| Method | 0-2.5 cm | 2.5-5 cm | 5-7.5 cm | 7.5-10 cm | Area (mean over 0-10 cm) |"
    assert table[2].startswith("| OmniD | **80.0 (49.0-94.3)** | **60.0 (31.3-83.2)** |")
    assert table[2].endswith("| 50.0 (35.2-64.8) |") and table[4].endswith("| — | — | — | — |")
    png = position_curve_chart(
        results, ("omnid", "diffusion", "act"), TASK0, bands, LABELS, tmp_path / "c.png"
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_offline_table_lowest_error_in_bold(tmp_path):
    paths = {}
    for method, error in (("omnid", 2.5), ("diffusion", 7.25)):
        paths[(method, TASK0, "id")] = tmp_path / f"{method}.json"
        hold = {"position_cm": 3.0, "gripper": 0.05}
        paths[(method, TASK0, "id")].write_text(
            json.dumps({"position_cm": error, "gripper": 0.125, "hold": hold})
        )
    paths[("omnid", TASK0, "ood1")] = tmp_path / "not_run.json"
    table = offline_table(paths, ("omnid", "diffusion"), TASK0, ("id", "ood1"), LABELS)
    assert table[0] == "| Method | id | ood1 |"
    assert table[2:] == [
        "| OmniD | **2.5 / 0.12** | — |",
        "| DP | 7.2 / 0.12 | — |",
        "| (holding the measured pose) | 3.0 / 0.05 | — |",
    ]
