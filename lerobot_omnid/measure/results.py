"""Results as success counts: one :class:`EvalRecord` per finished ``lerobot-eval`` run, read from its
``eval_info.json`` or from a run summary, merged across folders (runs made on other machines) and pooled per
table cell; and the one format of every protocol's run summary (:class:`RunSummary`).

A finished evaluation's counts come from its ``eval_info.json``, its commit and command from the engine's
stamp of the run. Every protocol writes its folder's ``summary.json`` in one format: the protocol, its
settings, every evaluation as a record, what is not a success count (open-loop and probe errors, seconds,
a selection) under ``results``, and the commit and command that wrote it; copying it (under
``docs/results/``) is enough to rebuild the protocol's report or to combine results of several machines.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lerobot_omnid.measure.stats import Estimate, wilson_interval

Key = tuple[str, str, str]
"""(model, task, setting): a table cell. model: a method, an ablation or a method whose fine-tuned model
the cell holds; setting: "id", "position_ood", "position_band_k", "ood1".."ood4" or "fewshot_a"."""

SUMMARY = "summary.json"
"""A protocol folder's run summary (:func:`write_run_summary`)."""
SUMMARY_FORMAT = 2
BENCHMARK = "omnid-benchmark"
COMPARABLE = {
    "episodes": None,
    "image_size": None,
    "steps": None,
    "batch_size": None,
    "episode_length": None,
    "finetune_steps": None,
    "small": None,
    "fuse_last_step_only": False,
    "task_steps": [],
}
"""Profile fields that must agree between folders whose results are combined (the models are the same
experiment; methods, tasks, settings, training and eval seeds and episodes per evaluation may differ), each
with the value a summary written before the field existed means."""


@dataclass(frozen=True)
class EvalEntry:
    """A finished evaluation of the plan: its cell, eval ``seed``, ``eval_info.json``, the training seed of
    its model, its control ("" for the checkpoint as trained), its command, the commit that ran it, the
    engine's fingerprint of the run and its tags (as :class:`EvalRecord`'s)."""

    key: Key
    seed: int | None
    path: Path
    train_seed: int | None = None
    control: str = ""
    command: tuple[str, ...] = ()
    commit: str | None = None
    fingerprint: str = ""
    tags: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class EvalRecord:
    """A finished evaluation: ``successes`` of ``episodes`` for one cell, control, training and eval seed.
    ``source``: the ``eval_info.json`` or summary file it was read from; ``commit``: the code commit that
    ran it (None if not recorded); ``tags``: what else tells this cell from others of the protocol, sorted
    (name, value) pairs (a rig, a training budget, a perturbation level); ``fingerprint``: the engine's
    fingerprint of the run that made it ("" if not recorded), by which a resumed campaign knows it done.
    """

    key: Key
    control: str
    train_seed: int | None
    eval_seed: int | None
    successes: int
    episodes: int
    source: str
    commit: str | None = None
    command: tuple[str, ...] = ()
    tags: tuple[tuple[str, str], ...] = ()
    fingerprint: str = ""

    @property
    def identity(self) -> tuple:
        """What makes two records the same evaluation (the same episodes of the same model)."""
        return (self.key, self.control, self.train_seed, self.eval_seed, self.tags)

    def tag(self, name: str) -> str | None:
        return dict(self.tags).get(name)

    def to_json(self) -> dict[str, Any]:
        model, task, setting = self.key
        return {
            "model": model,
            "task": task,
            "setting": setting,
            "control": self.control,
            "train_seed": self.train_seed,
            "eval_seed": self.eval_seed,
            "successes": self.successes,
            "episodes": self.episodes,
            "commit": self.commit,
            "command": list(self.command),
            "tags": dict(self.tags),
            **({"fingerprint": self.fingerprint} if self.fingerprint else {}),
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any], source: str) -> EvalRecord:
        """Parse :meth:`to_json`'s form; errors name ``source`` and the field."""
        try:
            record = cls(
                (str(data["model"]), str(data["task"]), str(data["setting"])),
                str(data["control"]),
                data["train_seed"],
                data["eval_seed"],
                int(data["successes"]),
                int(data["episodes"]),
                source,
                data.get("commit"),
                tuple(data.get("command", ())),
                tags_of(data.get("tags", {})),
                str(data.get("fingerprint", "")),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"{source}: expected an evaluation record with {e}, got {dict(data)}") from e
        if not 0 <= record.successes <= record.episodes or record.episodes < 1:
            raise ValueError(
                f"{source}: successes/episodes: expected 0 <= successes <= episodes and episodes >= 1, "
                f"got {record.successes}/{record.episodes}"
            )
        return record


def tags_of(tags: Mapping[str, Any]) -> tuple[tuple[str, str], ...]:
    """A record's tags from a mapping: sorted, values as strings."""
    return tuple(sorted((str(k), str(v)) for k, v in tags.items()))


@dataclass(frozen=True)
class CellResult:
    """Pooled counts of a cell: over its eval seeds and (unless chosen) its training seeds."""

    successes: int
    episodes: int
    sources: tuple[str, ...]

    @property
    def rate(self) -> float:
        """Success rate in %."""
        return 100.0 * self.successes / self.episodes

    @property
    def interval(self) -> Estimate:
        """Wilson 95 % interval of the rate, as fractions."""
        return wilson_interval(self.successes, self.episodes)


def read_eval_info(path: Path) -> tuple[int, int]:
    """(successful episodes, episodes) of one ``lerobot-eval`` run (its ``pc_success`` times its episodes)."""
    overall = json.loads(Path(path).read_text())["overall"]
    episodes = int(overall["n_episodes"])
    return round(float(overall["pc_success"]) * episodes / 100.0), episodes


def record_of(entry: EvalEntry) -> EvalRecord:
    """The record of a finished evaluation: its counts from its ``eval_info.json``."""
    successes, episodes = read_eval_info(entry.path)
    return EvalRecord(
        entry.key,
        entry.control,
        entry.train_seed,
        entry.seed,
        successes,
        episodes,
        str(entry.path),
        entry.commit,
        entry.command,
        entry.tags,
        entry.fingerprint,
    )


def collect(
    records: Iterable[EvalRecord], control: str = "", train_seed: int | None = None
) -> dict[Key, CellResult]:
    """Pool the records of ``control`` per cell, over every training seed or only ``train_seed``'s."""
    cells: dict[Key, CellResult] = {}
    for r in records:
        if r.control != control or (train_seed is not None and r.train_seed != train_seed):
            continue
        old = cells.get(r.key, CellResult(0, 0, ()))
        cells[r.key] = CellResult(
            old.successes + r.successes, old.episodes + r.episodes, (*old.sources, r.source)
        )
    return cells


def train_seeds(records: Iterable[EvalRecord]) -> list[int]:
    """The training seeds the records come from, sorted (records without one are left out)."""
    return sorted({r.train_seed for r in records if r.train_seed is not None})


@dataclass(frozen=True)
class RunSummary:
    """What a protocol's folder holds, in the one format every protocol writes: the ``protocol`` (its
    command or module), its ``settings``, every finished ``evaluations``, the ``results`` that are not
    success counts, and the ``commit`` and ``command`` that wrote it."""

    protocol: str
    settings: Mapping[str, Any]
    evaluations: Sequence[EvalRecord] = ()
    results: Mapping[str, Any] = field(default_factory=dict)
    commit: str | None = None
    command: Sequence[str] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "format": SUMMARY_FORMAT,
            "protocol": self.protocol,
            "settings": dict(self.settings),
            "commit": self.commit,
            "command": list(self.command),
            "evaluations": [r.to_json() for r in self.evaluations],
            "results": dict(self.results),
        }


def write_run_summary(path: Path, summary: RunSummary) -> Path:
    Path(path).write_text(json.dumps(summary.to_json(), indent=2) + "\n")
    return Path(path)


def read_run_summary(path: Path, protocol: str) -> RunSummary:
    """The run summary in ``path`` (a file, or a folder's ``summary.json``) written by ``protocol``; errors
    name the file, the field, what was expected and what was found."""
    path = Path(path)
    if path.is_dir():
        path = path / SUMMARY
    if not path.is_file():
        raise ValueError(
            f"{path}: expected a run summary of {protocol} (its folder's {SUMMARY}), got no such file"
        )
    data = json.loads(path.read_text())
    if data.get("format") != SUMMARY_FORMAT:
        raise ValueError(f"{path}: format: expected {SUMMARY_FORMAT}, got {data.get('format')!r}")
    if data.get("protocol") != protocol:
        raise ValueError(f"{path}: protocol: expected {protocol!r}, got {data.get('protocol')!r}")
    if missing := [k for k in ("settings", "evaluations", "results") if k not in data]:
        raise ValueError(f"{path}: expected the fields settings, evaluations and results, got no {missing}")
    return RunSummary(
        protocol,
        data["settings"],
        [EvalRecord.from_json(e, str(path)) for e in data["evaluations"]],
        data["results"],
        data.get("commit"),
        data.get("command", []),
    )


def merge_run_summaries(summaries: Sequence[RunSummary], sources: Sequence[str]) -> RunSummary:
    """One run summary of the evaluations of ``summaries`` (from the files ``sources``): the parts of one
    protocol run in several folders or sessions (e.g. one task each). They must share the protocol,
    settings and results; an evaluation in two of them is an error, not counted twice."""
    first, first_source = summaries[0], sources[0]
    seen: dict[tuple, str] = {}
    for summary, source in zip(summaries, sources, strict=True):
        for part in ("protocol", "settings", "results"):
            if getattr(summary, part) != getattr(first, part):
                raise ValueError(
                    f"{source}: {part}: expected those of {first_source} to merge with it, got "
                    f"{getattr(summary, part)!r} against {getattr(first, part)!r}"
                )
        for record in summary.evaluations:
            if record.identity in seen:
                raise ValueError(
                    f"{source}: evaluation {record.identity}: expected it in one summary only, got it in "
                    f"{seen[record.identity]} too"
                )
            seen[record.identity] = source
    commits = ", ".join(dict.fromkeys(s.commit for s in summaries if s.commit)) or None
    return RunSummary(
        first.protocol,
        first.settings,
        [r for s in summaries for r in s.evaluations],
        first.results,
        commits,
        first.command,
    )


def write_summary(
    path: Path,
    profile: Mapping[str, Any],
    tasks: Sequence[str],
    records: Sequence[EvalRecord],
    commit: str | None,
    command: Sequence[str],
    results: Mapping[str, Any] | None = None,
) -> Path:
    """Write a benchmark folder's ``summary.json``: its profile and tasks, the code commit and command that
    wrote it, every evaluation record of the folder (its own and those resumed from an earlier summary of
    the same plan, never ones merged with ``--also``) and its ``results`` that are not success counts."""
    settings = {"profile": dict(profile), "tasks": list(tasks)}
    return write_run_summary(path, RunSummary(BENCHMARK, settings, records, results or {}, commit, command))


def read_summary(path: Path) -> tuple[dict[str, Any], list[EvalRecord]]:
    """(profile, records) of a benchmark summary file, or of a benchmark folder's ``summary.json``."""
    summary = read_run_summary(path, BENCHMARK)
    return dict(summary.settings["profile"]), list(summary.evaluations)


def check_comparable(profile: Mapping[str, Any], other: Mapping[str, Any], source: str) -> None:
    """Raise ValueError naming the field if ``other`` (from ``source``) is not the same experiment."""
    for name, default in COMPARABLE.items():
        # As JSON reads them back: a profile's tuples are a summary's lists.
        mine, theirs = (json.loads(json.dumps(p.get(name, default))) for p in (profile, other))
        if mine != theirs:
            raise ValueError(
                f"{source}: {name}: expected {mine!r} as in this benchmark's profile, got {theirs!r} "
                "(results of different experiments are not combined)"
            )


def merge(groups: Iterable[Sequence[EvalRecord]]) -> list[EvalRecord]:
    """Records of several folders in one list. The same evaluation found twice (a folder and its copied
    summary) is kept once if its counts agree; if they differ, a ValueError names both sources."""
    merged: dict[tuple, EvalRecord] = {}
    for records in groups:
        for r in records:
            seen = merged.get(r.identity)
            if seen is None:
                merged[r.identity] = r
            elif (seen.successes, seen.episodes) != (r.successes, r.episodes):
                model, task, setting = r.key
                raise ValueError(
                    f"{model}/{task}/{setting} control {r.control or 'none'} training seed {r.train_seed} "
                    f"eval seed {r.eval_seed}: expected one result, got {seen.successes}/{seen.episodes} in "
                    f"{seen.source} and {r.successes}/{r.episodes} in {r.source} (give each machine its own "
                    "training or eval seeds)"
                )
    return list(merged.values())
