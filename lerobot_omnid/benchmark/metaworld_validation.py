"""Choosing OmniD's feature stage for MetaWorld on validation seeds, before the comparison's other tasks.

At the comparison's 64 px, stride-16 features are 4x4 maps: one cell per 16 px, while MetaWorld's objects
span a few pixels of a fixed camera. The protocol
(docs/benchmark.md#metaworld-the-feature-stage-on-validation), fixed before any of its runs:

1. *Data*: ``TASK``'s demonstrations of the comparison (same command and folder, so its run is reused).
2. *Candidates* (``CANDIDATES``): OmniD on the four cameras exactly as the comparison trains it, but for
   the last ResNet stage it samples: 3 (the comparison's, stride 16; its ``train/omnid`` model), 2 (stride
   8, 8x8 maps) and 1 (stride 4, 16x16 maps); the same data, steps and seed.
3. *Validation*, never reported as a result: ``lerobot-eval`` on env seeds ``VALIDATION_SEED`` ...
   (``VALIDATION_EPISODES`` episodes), disjoint from the demonstrations' (0-9) and the test's (1000-1014,
   2000-2014), with each candidate's blind control (every camera black) on the same seeds.
4. *Rule* (:func:`choose`): among the candidates with more validation successes than their blind control,
   the one with the most; ties go to the comparison's stage, then to the cheaper (the earlier stage);
   if none qualifies, the comparison's stage stays. The chosen stage is the one every OmniD of the
   comparison's remaining tasks is trained with.

Runs on the experiment engine (resumable; ``--dry-run`` prints every command); writes ``<out>/report.md``
and ``<out>/summary.json``; ``--report-only --summary FILE`` rebuilds the report from such a summary.

    MUJOCO_GL=egl python -m lerobot_omnid.benchmark.metaworld_validation --out outputs/metaworld_validation
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from pathlib import Path

from gym_omnid.metaworld_suite import DEFAULT_CAMERAS

from lerobot_omnid.benchmark import metaworld_comparison as comparison
from lerobot_omnid.benchmark.metaworld_comparison import Model
from lerobot_omnid.measure.engine import Run, evaluations, protocol_main
from lerobot_omnid.measure.report import format_counts, format_p, markdown_table, write_markdown
from lerobot_omnid.measure.results import CellResult, EvalRecord, RunSummary, collect
from lerobot_omnid.measure.stats import fisher_exact

PROTOCOL = "metaworld_validation"
TASK = "push-v3"
CANDIDATES = {  # in the rule's tie order: the comparison's stage, then the cheaper first
    "omnid": Model("omnid", DEFAULT_CAMERAS),
    "omnid_layer1": Model("omnid", DEFAULT_CAMERAS, backbone_layer=1),
    "omnid_layer2": Model("omnid", DEFAULT_CAMERAS, backbone_layer=2),
}
VALIDATION_SEED = 3000
VALIDATION_EPISODES = 20
STAGE = "validation"


def protocol(out: Path) -> list[Run]:
    """Record ``TASK`` (the comparison's run), train every candidate, validate it and its blind control."""
    return comparison.protocol(out, [TASK], CANDIDATES, (VALIDATION_SEED,), VALIDATION_EPISODES, STAGE)


def choose(cells: Mapping[tuple[str, str], CellResult]) -> str | None:
    """The rule on ``cells`` ((candidate, control) -> counts; control "" or "blind"): the chosen candidate's
    name, or None while a candidate's validation or blind control is missing."""
    if any((name, control) not in cells for name in CANDIDATES for control in ("", "blind")):
        return None
    above = [n for n in CANDIDATES if cells[n, ""].successes > cells[n, "blind"].successes]
    return max(above, key=lambda n: cells[n, ""].successes, default=next(iter(CANDIDATES)))


def validation_cells(records: Sequence[EvalRecord]) -> dict[tuple[str, str], CellResult]:
    """(candidate, control) -> the counts of its validation."""
    return {
        (key[0], control): cell
        for control in ("", "blind")
        for key, cell in collect(records, control).items()
    }


def summarise(runs: Sequence[Run], commit: str | None = None) -> RunSummary:
    """Every finished validation of this plan and the rule's choice (``results["chosen"]``, with each
    candidate's stage)."""
    settings = {
        "task": TASK,
        "validation_seed": VALIDATION_SEED,
        "validation_episodes": VALIDATION_EPISODES,
        "image_size": comparison.IMAGE_SIZE,
        "steps": comparison.STEPS,
    }
    records = evaluations(runs)
    stages = {name: model.backbone_layer for name, model in CANDIDATES.items()}
    results = {"stages": stages, "chosen": choose(validation_cells(records))}
    return RunSummary(PROTOCOL, settings, records, results, commit)


def write_report(summary: RunSummary, path: Path) -> None:
    """``report.md``: each candidate's validation success, its blind control, Fisher p between them and the
    rule's choice."""
    settings, results = summary.settings, summary.results
    cells = validation_cells(summary.evaluations)
    first = settings["validation_seed"]
    rows = []
    for name, stage in results["stages"].items():
        seen, blind = cells.get((name, "")), cells.get((name, "blind"))
        p = (
            format_p(fisher_exact(seen.successes, seen.episodes, blind.successes, blind.episodes))
            if seen and blind
            else ""
        )
        side = settings["image_size"] // 2 ** (stage + 1)
        chosen = "**chosen**" if name == results["chosen"] else ""
        rows.append([name, f"{stage} ({side}x{side})", format_counts(seen), format_counts(blind), p, chosen])
    lines = [
        "# MetaWorld: OmniD's feature stage on validation seeds",
        "",
        f"`{settings['task']}`, {settings['image_size']} px, {settings['steps']} training steps; env seeds "
        f"{first}-{first + settings['validation_episodes'] - 1}. Rule: the most successes among the "
        "candidates above their blind control (ties: the comparison's stage, then the cheaper).",
        "",
        *markdown_table(
            ["candidate", "ResNet stage (map)", "validation", "blind control", "Fisher p", ""], rows
        ),
    ]
    if results["chosen"] is None:
        lines += ["", "Not decided: a validation is missing."]
    write_markdown(lines, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/metaworld_validation"))
    return protocol_main(parser, argv, PROTOCOL, lambda _, out: protocol(out), summarise, write_report)


if __name__ == "__main__":
    raise SystemExit(main())
