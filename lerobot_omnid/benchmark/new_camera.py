"""A new camera from ten episodes: which recipe, chosen on validation before any test run.

The protocol (docs/benchmark.md#a-new-camera-its-protocol), fixed before any of its runs:

1. *Data*: the benchmark's ``mini`` training set of ``select_apple`` (cameras B-E) and its few-shot set
   (10 episodes seen by camera A only, from env seed 100000), recorded by ``omnid-benchmark``'s own commands
   into the same folders.
2. *Pre-trained models* (``PRETRAINED``), OmniD with the ``mini`` options, ``--seed=1000``: ``mini`` itself
   (the benchmark's run) and ``single_camera``, trained with half of its samples fused from one camera
   (``--policy.single_camera_rate=0.5``), so that the OFG learns to lift the scene from a single view.
3. *Hypotheses* (``HYPOTHESES``): a pre-trained model fine-tuned on the camera-A episodes for some steps at
   some learning rate, some parts frozen: the paper's recipe at CPU size (``mini``, 200 steps, the
   benchmark's), longer fine-tuning (1000 steps), longer at a lower learning rate (1e-4), longer from
   ``single_camera``, longer with the diffusion head frozen, longer with the backbone frozen, longer with
   as many B-E training episodes replayed beside the camera-A ones (``REPLAY_DATA``).
   Zero-shot (no fine-tuning) each pre-trained model is evaluated on camera A too.
4. *Validation*, never reported as a result: ``lerobot-eval`` with camera A only, ID, env seeds
   ``VALIDATION_SEED`` ... (``VALIDATION_EPISODES``), disjoint from every other seed set; the policy reads
   camera A's calibration from the env's every frame.
5. *Rule* (:func:`select`): the most validation successes; among those within ``TIE_MARGIN`` of the
   most, the fewest fine-tuning steps, then the order of ``HYPOTHESES`` (the paper's first).
6. *Test*, once selected, on ``select_apple`` and ``select_chemistry_tube`` with two training seeds: the
   selected recipe and the paper's, OmniD and DP (DP: the same steps and learning rate, every weight
   trained, camera A alone: single-camera pre-training, frozen parts and replay are OmniD's own), 30
   episodes per cell on two disjoint env-seed ranges, blind controls, the probe error beside each model.
   This module plans the validation. The test is the benchmark's few-shot phase with the selected recipe
   beside the paper's (``BenchmarkProfile.fewshot_recipes``; each hypothesis is a
   :class:`~lerobot_omnid.benchmark.methods.FewshotRecipe`), in a profile committed once it is selected; run
   with this protocol's ``--out``, it reuses its recordings and pre-trained models (the same commands).

Runs on the experiment engine (resumable; ``--dry-run`` prints every command); writes ``report.md``,
``summary.json`` and, once every hypothesis is validated, ``selection.json`` in ``<out>/validation/`` (the
test's own report and summary go to ``<out>``).

    MUJOCO_GL=egl python -m lerobot_omnid.benchmark.new_camera --out outputs/new_camera
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path

from gym_omnid import TRAIN_CAMERAS

from lerobot_omnid.benchmark import commands
from lerobot_omnid.benchmark.methods import (
    CAMERA_A,
    PAPER_RECIPE,
    SINGLE_CAMERA,
    FewshotRecipe,
    method_flags,
    recipe_flags,
    variant_flags,
)
from lerobot_omnid.benchmark.plan import FEWSHOT_SEED, MINI, REPLAY, TASK0, TRAIN_SEED, replay_runs
from lerobot_omnid.keys import image_key
from lerobot_omnid.measure.engine import CHECKPOINT, Run, evaluations, plan, protocol_main
from lerobot_omnid.measure.report import write_markdown
from lerobot_omnid.measure.results import RunSummary
from lerobot_omnid.measure.stats import wilson_interval

PRETRAINED = {"mini": "", "single_camera": SINGLE_CAMERA.name}  # name: the variant it is ("": mini's OmniD)
LONG = 1000  # fine-tuning steps of the longer recipes
HYPOTHESES = {  # name: the recipe (the benchmark's few-shot recipes are these, once one is selected)
    "paper": dataclasses.replace(PAPER_RECIPE, name="paper", steps=MINI.finetune_steps),
    "long": FewshotRecipe("long", f"{LONG} steps", LONG),
    "long_low_lr": FewshotRecipe("long_low_lr", f"{LONG} steps at lr 1e-4", LONG, lr=1e-4),
    "single_camera_long": FewshotRecipe(
        "single_camera_long", f"{LONG} steps from single-camera pre-training", LONG, start=SINGLE_CAMERA.name
    ),
    # The plane is meant to be camera-agnostic: keep what maps it to actions, adapt only the lifting.
    "long_frozen_head": FewshotRecipe(
        "long_frozen_head", f"{LONG} steps, head frozen", LONG, frozen=("head",)
    ),
    # The ResNet's features are generic: adapt the OFG and the head only.
    "long_frozen_backbone": FewshotRecipe(
        "long_frozen_backbone", f"{LONG} steps, backbone frozen", LONG, frozen=("backbone",)
    ),
    # Fine-tuning on camera A alone may make the plane forget B-E: keep showing them.
    "long_replay": FewshotRecipe("long_replay", f"{LONG} steps with B-E replayed", LONG, replay=True),
}
VALIDATION_SEED = 70_000
VALIDATION_EPISODES = 20
TIE_MARGIN = 1
SELECTION_FILE = "selection.json"
PROTOCOL = "new_camera"
TRAIN_DATA, FEWSHOT_DATA = f"{TASK0}_bcde", f"{TASK0}_a_fewshot"  # the benchmark's folder names
REPLAY_DATA = FEWSHOT_DATA + REPLAY  # the replay hypotheses' fine-tuning set, the benchmark's


def pretrained_name(recipe: FewshotRecipe) -> str:
    return next(name for name, variant in PRETRAINED.items() if variant == recipe.start)


def pretrained_dir(out: Path, name: str) -> Path:
    """The benchmark's own folder of the model (a profile with the variant trains it there too)."""
    return out / "train" / (PRETRAINED[name] or "omnid") / TASK0


def finetuned_dir(out: Path, hypothesis: str) -> Path:
    return out / "finetune_validation" / hypothesis


def results_dir(out: Path) -> Path:
    """Where the report, the summary and the selection go: not ``out`` itself, whose ``summary.json`` and
    ``report.md`` are the test's (``omnid-benchmark --profile new-camera`` runs in the same ``--out``)."""
    return out / "validation"


def validation_dir(out: Path, model: str) -> Path:
    return results_dir(out) / model


def records(out: Path) -> list[Run]:
    """The B-E training set and the camera-A few-shot set, as ``omnid-benchmark`` records them."""
    train = out / "data" / TRAIN_DATA
    fewshot = out / "data" / FEWSHOT_DATA
    p = MINI
    cmd_train = commands.record_command(TASK0, p.episodes, TRAIN_CAMERAS, p.image_size, train, seed=0)
    cmd_fewshot = commands.record_command(
        TASK0, p.fewshot_episodes, CAMERA_A, p.image_size, fewshot, seed=FEWSHOT_SEED
    )
    runs = [
        Run(f"record/{TRAIN_DATA}", "record", tuple(cmd_train), train, episodes=p.episodes),
        Run(f"record/{FEWSHOT_DATA}", "record", tuple(cmd_fewshot), fewshot, episodes=p.fewshot_episodes),
    ]
    if any(recipe.replay for recipe in HYPOTHESES.values()):
        runs += replay_runs(p, out, TASK0)
    return runs


def pretrain(out: Path, name: str) -> list[str]:
    flags = ["--policy.type=omnid", "--policy.device=cpu", "--policy.push_to_hub=false"]
    variant = SINGLE_CAMERA if PRETRAINED[name] else None
    options = variant_flags(variant, MINI) if variant else method_flags("omnid", MINI)
    flags += [flag for flag, _ in options]
    return commands.train_command(
        out / "data" / TRAIN_DATA,
        pretrained_dir(out, name),
        flags,
        MINI.steps,
        MINI.batch_size,
        seed=TRAIN_SEED,
    )


def finetune(out: Path, hypothesis: str) -> list[str]:
    recipe = HYPOTHESES[hypothesis]
    start = pretrained_dir(out, pretrained_name(recipe)) / CHECKPOINT
    flags = [f"--policy.path={start}", "--policy.device=cpu", "--policy.push_to_hub=false"]
    flags += [flag for flag, _ in recipe_flags("omnid", recipe)]
    return commands.train_command(
        out / "data" / (REPLAY_DATA if recipe.replay else FEWSHOT_DATA),
        finetuned_dir(out, hypothesis),
        flags,
        recipe.steps,
        MINI.batch_size,
        seed=TRAIN_SEED,
    )


def evaluation(out: Path, checkpoint: Path, model: str, trained: str) -> Run:
    """Camera A only, ID, the validation seeds; its calibration read from the env's every frame.
    ``trained``: the name of the run that makes ``checkpoint``."""
    extra = [
        f"--env.episode_length={MINI.episode_length}",
        "--env.per_frame_calibration=true",
        "--policy.cameras=" + commands.json_list(CAMERA_A),
        "--policy.frame_calibration=" + commands.json_list([image_key(c) for c in CAMERA_A]),
    ]
    cmd = commands.eval_command(
        checkpoint,
        validation_dir(out, model),
        TASK0,
        "id",
        CAMERA_A,
        MINI.image_size,
        VALIDATION_EPISODES,
        "cpu",
        seed=VALIDATION_SEED,
        extra=extra,
        batch_size=min(MINI.eval_batch_size, VALIDATION_EPISODES),
    )
    return Run(
        f"validation/{model}",
        "eval",
        tuple(cmd),
        validation_dir(out, model),
        (trained,),
        result=(model, TASK0, "validation"),
        seed=VALIDATION_SEED,
        train_seed=TRAIN_SEED,
    )


def protocol(out: Path) -> list[Run]:
    """Record, pre-train, validate zero-shot, fine-tune per hypothesis, validate."""
    runs = records(out)
    for name in PRETRAINED:
        folder = pretrained_dir(out, name)
        trained = Run(
            str(folder.relative_to(out)), "train", tuple(pretrain(out, name)), folder, (runs[0].name,)
        )
        runs.append(trained)
        runs.append(evaluation(out, folder / CHECKPOINT, f"zero_shot_{name}", trained.name))
    for hypothesis, recipe in HYPOTHESES.items():
        name = str(finetuned_dir(out, hypothesis).relative_to(out))
        data = f"merge/{REPLAY_DATA}" if recipe.replay else runs[1].name
        needs = (str(pretrained_dir(out, pretrained_name(recipe)).relative_to(out)), data)
        runs.append(
            Run(name, "train", tuple(finetune(out, hypothesis)), finetuned_dir(out, hypothesis), needs)
        )
        runs.append(evaluation(out, finetuned_dir(out, hypothesis) / CHECKPOINT, hypothesis, name))
    return plan(runs, out)


def select(results: dict[str, tuple[int, int]]) -> str:
    """The protocol's rule: the most validation successes; within ``TIE_MARGIN`` of the most, the fewest
    fine-tuning steps, then the order of ``HYPOTHESES``."""
    best = max(results[h][0] for h in HYPOTHESES)
    close = [h for h in HYPOTHESES if results[h][0] >= best - TIE_MARGIN]
    return min(close, key=lambda h: HYPOTHESES[h].steps)


def summarise(runs: Sequence[Run], commit: str | None = None) -> RunSummary:
    """Each model's validation counts and the commit that made them (of the runs done for this plan), and
    the selection once every hypothesis is validated."""
    records = evaluations(runs)
    validated = {r.key[0]: (r.successes, r.episodes) for r in records if r.key[0] in HYPOTHESES}
    settings = {
        "task": TASK0,
        "validation_seed": VALIDATION_SEED,
        "validation_episodes": VALIDATION_EPISODES,
        "hypotheses": {h: dataclasses.asdict(recipe) for h, recipe in HYPOTHESES.items()},
    }
    selected = select(validated) if len(validated) == len(HYPOTHESES) else None
    return RunSummary(PROTOCOL, settings, records, {"selected": selected}, commit)


def write_report(summary: RunSummary, path: Path) -> None:
    """``report.md``: each model's validation success on camera A, and the selection."""
    settings = summary.settings
    first = settings["validation_seed"]
    lines = [
        f"# A new camera from ten episodes: validation ({settings['task']}, camera A)",
        "",
        f"Env seeds {first}-{first + settings['validation_episodes'] - 1}, camera A only. Rule: the most "
        f"successes; within {TIE_MARGIN} of the most, the fewest fine-tuning steps.",
        "",
        "| model | pre-trained | fine-tuning | validation success (Wilson 95 %) | selected |",
        "|---|---|---|---|---|",
    ]
    for result in summary.evaluations:
        model = result.key[0]
        est = wilson_interval(result.successes, result.episodes)
        hypothesis = settings["hypotheses"].get(model)
        if hypothesis:
            lr = "mini's lr" if hypothesis["lr"] is None else f"lr {hypothesis['lr']:g}"
            frozen = ", ".join(hypothesis.get("frozen", ()))
            pretrained = pretrained_name(FewshotRecipe(**hypothesis))
            tuning = f"{hypothesis['steps']} steps, {lr}" + (f", {frozen} frozen" if frozen else "")
            tuning += ", B-E episodes replayed" if hypothesis.get("replay") else ""
        else:
            pretrained, tuning = model.removeprefix("zero_shot_"), "none (zero-shot)"
        chosen = "**yes**" if model == summary.results["selected"] else ""
        lines.append(
            f"| {model} | {pretrained} | {tuning} | {result.successes}/{result.episodes} "
            f"({100 * est.low:.1f}-{100 * est.high:.1f} %) | {chosen} |"
        )
    write_markdown(lines, path)


def write_selection(summary: RunSummary, results: Path) -> None:
    """``selection.json``, once: the hypothesis the rule selects when every one is validated."""
    selected = summary.results["selected"]
    if selected and not (results / SELECTION_FILE).is_file():
        selection = {"selected": selected, "rule": select.__doc__, "commit": summary.commit}
        (results / SELECTION_FILE).write_text(json.dumps(selection, indent=2) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/new_camera"))
    return protocol_main(
        parser,
        argv,
        PROTOCOL,
        lambda _, out: protocol(out),
        summarise,
        write_report,
        results_dir=results_dir,
        after_summary=write_selection,
    )


if __name__ == "__main__":
    raise SystemExit(main())
