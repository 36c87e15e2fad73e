"""The rule that picks, for each method with variants, one model on validation: the position validation's
(docs/benchmark.md#position-its-protocol), fixed before its runs.

Candidates of a method: the method as trained and its variants, in the profile's order. Score: successes
in the profile's position bands, pooled. Eligible: ID successes at most ``ID_GUARD`` below the method as
trained (a variant that buys the bands with the square is not chosen). Chosen: among the eligible within
``TIE_MARGIN`` of the best score, the first in the profile's order (the method as trained first, then the
variants with the fewest changes).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from lerobot_omnid.benchmark.plan import BANDS, TASK0, BenchmarkProfile
from lerobot_omnid.measure.report import markdown_table
from lerobot_omnid.measure.results import CellResult, Key

ID_GUARD = 2
TIE_MARGIN = 1


@dataclass(frozen=True)
class Candidate:
    model: str
    id_successes: int
    band_successes: int
    band_episodes: int
    eligible: bool


def candidates(cells: Mapping[Key, CellResult], p: BenchmarkProfile, method: str) -> list[Candidate] | None:
    """``method``'s candidates with their validation counts; None until every one has every cell. The
    rule counts successes: every candidate must have as many episodes in each setting."""
    models = [method, *(v.name for v in p.variants if v.method == method)]
    bands = [b for b in BANDS if b in p.settings]
    if any((m, TASK0, s) not in cells for m in models for s in ("id", *bands)):
        return None
    for setting in ("id", *bands):
        episodes = {m: cells[(m, TASK0, setting)].episodes for m in models}
        if len(set(episodes.values())) > 1:
            raise ValueError(f"{setting}: expected the same episodes for every candidate, got {episodes}")
    base_id = cells[(method, TASK0, "id")].successes
    found = []
    for m in models:
        id_successes = cells[(m, TASK0, "id")].successes
        band = [cells[(m, TASK0, b)] for b in bands]
        eligible = id_successes >= base_id - ID_GUARD
        found.append(
            Candidate(
                m, id_successes, sum(c.successes for c in band), sum(c.episodes for c in band), eligible
            )
        )
    return found


def select(found: list[Candidate]) -> str:
    """The rule of the module docstring."""
    eligible = [c for c in found if c.eligible]  # the method as trained always is
    best = max(c.band_successes for c in eligible)
    return next(c.model for c in eligible if c.band_successes >= best - TIE_MARGIN)


def selection_lines(
    cells: Mapping[Key, CellResult], p: BenchmarkProfile, labels: Mapping[str, str]
) -> list[str]:
    """The report's section: each method's candidates, their counts and the one chosen (or what is
    missing)."""
    lines = [
        "",
        "## Variants on validation: the choice",
        "",
        f"Score: successes in the bands pooled; eligible: ID successes at most {ID_GUARD} below the method "
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
                    f"{c.band_successes}/{c.band_episodes}",
                    "yes" if c.eligible else "no",
                    "**chosen**" if c.model == chosen else "",
                ]
            )
    return lines + markdown_table(["Model", "ID", "Bands pooled", "Eligible", ""], rows)
