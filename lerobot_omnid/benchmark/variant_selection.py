"""The rule that picks, for each method with variants, one model on validation: the position and the
moved-rig validations' (docs/benchmark.md#position-its-protocol, #moved-rigs-its-protocol), fixed before
their runs.

Candidates of a method: the method as trained and its variants, in the profile's order. Score: successes
in the profile's settings beyond ID (the position bands, or the unseen rigs), pooled. Eligible: ID
successes at most ``ID_GUARD`` below the method as trained (a variant that buys the new settings with the
old is not chosen). Chosen: among the eligible within ``TIE_MARGIN`` of the best score, the first in the
profile's order (the method as trained first, then the variants with the fewest changes).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from lerobot_omnid.benchmark.plan import TASK0, BenchmarkProfile
from lerobot_omnid.measure.report import markdown_table
from lerobot_omnid.measure.results import CellResult, Key

ID_GUARD = 2
TIE_MARGIN = 1


@dataclass(frozen=True)
class Candidate:
    model: str
    id_successes: int
    scored_successes: int  # in the settings beyond ID, pooled
    scored_episodes: int
    eligible: bool


def candidates(cells: Mapping[Key, CellResult], p: BenchmarkProfile, method: str) -> list[Candidate] | None:
    """``method``'s candidates with their validation counts; None until every one has every cell. The
    rule counts successes: every candidate must have as many episodes in each setting."""
    models = [method, *(v.name for v in p.variants if v.method == method)]
    scored = [s for s in p.settings if s != "id"]
    if any((m, TASK0, s) not in cells for m in models for s in ("id", *scored)):
        return None
    for setting in ("id", *scored):
        episodes = {m: cells[(m, TASK0, setting)].episodes for m in models}
        if len(set(episodes.values())) > 1:
            raise ValueError(f"{setting}: expected the same episodes for every candidate, got {episodes}")
    base_id = cells[(method, TASK0, "id")].successes
    found = []
    for m in models:
        id_successes = cells[(m, TASK0, "id")].successes
        beyond = [cells[(m, TASK0, s)] for s in scored]
        eligible = id_successes >= base_id - ID_GUARD
        found.append(
            Candidate(
                m, id_successes, sum(c.successes for c in beyond), sum(c.episodes for c in beyond), eligible
            )
        )
    return found


def select(found: list[Candidate]) -> str:
    """The rule of the module docstring."""
    eligible = [c for c in found if c.eligible]  # the method as trained always is
    best = max(c.scored_successes for c in eligible)
    return next(c.model for c in eligible if c.scored_successes >= best - TIE_MARGIN)


def selection_lines(
    cells: Mapping[Key, CellResult], p: BenchmarkProfile, labels: Mapping[str, str]
) -> list[str]:
    """The report's section: each method's candidates, their counts and the one chosen (or what is
    missing)."""
    lines = [
        "",
        "## Variants on validation: the choice",
        "",
        f"Score: successes beyond ID ({', '.join(s for s in p.settings if s != 'id')}) pooled; eligible: ID "
        f"successes at most {ID_GUARD} below the method "
        f"as trained; chosen: the first eligible (profile order, as trained first) within {TIE_MARGIN} of "
        "the best score (lerobot_omnid.benchmark.variant_selection).",
        "",
    ]
    rows = []
    for method in dict.fromkeys(v.method for v in p.variants):
        found = candidates(cells, p, method)
        if found is None:
            rows.append([labels[method], "not every candidate evaluated yet", "", "", ""])
            continue
        chosen = select(found)
        for c in found:
            episodes = cells[(c.model, TASK0, "id")].episodes
            rows.append(
                [
                    labels[c.model],
                    f"{c.id_successes}/{episodes}",
                    f"{c.scored_successes}/{c.scored_episodes}",
                    "yes" if c.eligible else "no",
                    "**chosen**" if c.model == chosen else "",
                ]
            )
    return lines + markdown_table(["Model", "ID", "Beyond ID, pooled", "Eligible", ""], rows)
