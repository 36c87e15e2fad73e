"""The position validation's rule: the most band successes among the variants that keep the square, ties to
the simplest; nothing chosen before every candidate is evaluated; the report's section."""

from __future__ import annotations

import dataclasses

import pytest

from lerobot_omnid.benchmark import new_camera, readout_selection, task_sizing
from lerobot_omnid.benchmark.plan import BANDS, EVAL_SEED_STRIDE, FEWSHOT_SEED, HELDOUT_SEED, PROFILES, TASK0
from lerobot_omnid.benchmark.variant_selection import Candidate, candidates, select, selection_lines
from lerobot_omnid.diagnostics.action_reach import REACH_SEED
from lerobot_omnid.diagnostics.position_extrapolation import PROBE_SEED
from lerobot_omnid.measure.results import CellResult

P = PROFILES["position-validation"]
OMNID_MODELS = ("omnid", "omnid_clip2", "omnid_clip2_shift5", "omnid_clip2_shift10")


def cells_of(counts: dict[str, tuple[int, int]]) -> dict:
    """Cells from (ID successes, successes per band) of each model, 10 episodes per cell."""
    cells = {}
    for model, (id_successes, per_band) in counts.items():
        cells[(model, TASK0, "id")] = CellResult(id_successes, 10, ())
        for band in BANDS:
            cells[(model, TASK0, band)] = CellResult(per_band, 10, ())
    return cells


@pytest.mark.parametrize(
    ("counts", "chosen"),
    [
        ([(8, 0), (8, 1), (7, 3), (6, 2)], "omnid_clip2_shift5"),  # the most band successes wins
        # A variant that loses the square (ID 3 below as trained) is not eligible, however good its bands.
        ([(8, 0), (8, 1), (5, 5), (7, 0)], "omnid_clip2"),
        ([(8, 1), (8, 1), (8, 1), (8, 1)], "omnid"),  # all equal: the first in the profile's order
    ],
)
def test_rule(counts, chosen):
    """``counts``: (ID successes, successes per band) of the OmniD candidates in the profile's order."""
    found = candidates(cells_of(dict(zip(OMNID_MODELS, counts, strict=True))), P, "omnid")
    assert [c.model for c in found] == list(OMNID_MODELS)
    assert select(found) == chosen


def test_a_tie_within_the_margin_goes_to_the_simpler_model():
    found = candidates(cells_of({m: (8, 0) for m in OMNID_MODELS}), P, "omnid")
    found[2] = Candidate("omnid_clip2_shift5", 8, 1, 40, True)  # one more band success: a tie
    assert select(found) == "omnid"
    found[3] = Candidate("omnid_clip2_shift10", 8, 3, 40, True)  # three more: alone at the top
    assert select(found) == "omnid_clip2_shift10"


def test_nothing_is_chosen_before_every_candidate_is_evaluated():
    cells = cells_of({m: (8, 0) for m in OMNID_MODELS})
    del cells[("omnid_clip2_shift10", TASK0, BANDS[-1])]
    assert candidates(cells, P, "omnid") is None
    lines = selection_lines(cells, P, P.labels)
    assert any("OmniD | not every candidate evaluated yet" in line for line in lines)
    assert any(line.startswith("| DP | not every candidate") for line in lines)
    full = cells_of({"diffusion": (5, 0), "diffusion_clip2": (5, 2)})
    chosen = [line for line in selection_lines(full, P, P.labels) if "**chosen**" in line]
    assert chosen == ["| DP clip 2 | 5/10 | 8/40 | yes | **chosen** |"]


def test_validation_seeds_are_disjoint_from_every_other_seed_set():
    def seeds(first: int, n: int = 1000) -> set[int]:
        return set(range(first, first + n))

    validation = {s for k in P.eval_seeds for s in seeds(k * EVAL_SEED_STRIDE, P.eval_episodes)}
    test = {s for k in range(1, 50) for s in seeds(k * EVAL_SEED_STRIDE, 50)}  # every test range
    others = seeds(0) | seeds(FEWSHOT_SEED) | seeds(HELDOUT_SEED) | seeds(PROBE_SEED) | seeds(REACH_SEED)
    others |= seeds(readout_selection.VALIDATION_SEED) | seeds(task_sizing.VALIDATION_SEED)
    others |= seeds(new_camera.VALIDATION_SEED)
    assert validation and not validation & (test | others)


def test_candidates_must_have_as_many_episodes_and_variants_a_trained_method():
    cells = cells_of({m: (8, 0) for m in OMNID_MODELS})
    cells[("omnid_clip2", TASK0, "id")] = CellResult(8, 20, ())  # evaluated twice as often
    with pytest.raises(ValueError, match=r"id: expected the same episodes for every candidate"):
        candidates(cells, P, "omnid")
    with pytest.raises(
        ValueError, match=r"variants: expected distinct new names of methods among \['omnid'\]"
    ):
        dataclasses.replace(P, methods=("omnid",))
    with pytest.raises(ValueError, match="got 'omnid_clip2' of 'omnid'"):
        dataclasses.replace(P, variants=(*P.variants, P.variants[0]))
