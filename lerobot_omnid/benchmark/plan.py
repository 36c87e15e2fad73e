"""What ``omnid-benchmark`` runs: its profiles and the plan of record / train / eval runs (each method's
LeRobot options, with their reasons, come from :mod:`lerobot_omnid.benchmark.methods`).

Pure: builds command lines and paths from a profile, runs nothing. The protocol (docs/benchmark.md, section 4
of the paper): cameras B-E for training; every task's ID success; on task 0 (on every task with
``every_task``) the profile's settings (position OOD, the graded position bands, background OODs) and each
method's controls (the same checkpoint blind; OmniD with its cameras' calibrations permuted or perturbed);
the task-0 model fine-tuned with camera-A episodes of task 0 and of task 1; OmniD ablations; each fine-tuned
model's blind control; with ``multitask``, one model per method trained on every task together. Everything
after the recordings is repeated per training seed.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import gym_omnid.constants
from gym_omnid import TRAIN_CAMERAS
from gym_omnid.constants import POSITION_BANDS

from lerobot_omnid.benchmark.commands import (
    BIN,
    control_calibration_command,
    eval_command,
    json_list,
    merge_command,
    record_command,
    train_command,
)
from lerobot_omnid.benchmark.methods import (
    ABLATIONS,
    CAMERA_A,
    CONTROLS,
    METHODS,
    PAPER_RECIPE,
    POSITION_VARIANTS,
    RIG_VARIANTS,
    VQBET_CAMERA,
    FewshotRecipe,
    Variant,
    ablation_flags,
    control_flags,
    fewshot_model,
    method_controls,
    method_flags,
    recipe_flags,
    variant_flags,
)
from lerobot_omnid.keys import image_key
from lerobot_omnid.measure.engine import CHECKPOINT as CHECKPOINT_SUBDIR
from lerobot_omnid.measure.engine import Run, plan

MULTITASK_METHODS = ("omnid", "diffusion")
MULTITASK_DATASET = "all_tasks_bcde_onehot"
MULTITASK = "_multitask"
"""Suffix of a method's model trained on every task together, told the task by a one-hot in
``observation.environment_state`` (``omnid-record --task-onehot``, ``--env.task_onehot=true``)."""
LABELS = {
    "omnid": "OmniD",
    "diffusion": "DP",
    "act": "ACT",
    "vqbet": "VQ-BeT",
    "omnid_multitask": "OmniD multi-task",
    "diffusion_multitask": "DP multi-task",
    "omnid_resnet101": "OmniD ResNet-101",
    "omnid_no_ofg": "OmniD w/o OFG",
    "omnid_cam_a": "OmniD camera A",
}
TASK0, TASK1 = "select_apple", "select_chemistry_tube"  # the paper's task 0 and task 1
BACKGROUND_OODS = ("ood1", "ood2", "ood3", "ood4")
BANDS = tuple(POSITION_BANDS)  # position_band_1 .. _4: the position-shift curve's settings
SETTINGS = ("id", "position_ood", *BACKGROUND_OODS, *BANDS)
UNSEEN_RIGS = ("higher", "bumped")  # gym_omnid.RIGS that no training set of the benchmark has
RIG_SETTINGS = tuple(f"rig_{rig}" for rig in UNSEEN_RIGS)
"""Settings of the ID layouts seen by a moved rig, whose true calibration OmniD reads from every frame."""
FEWSHOT = "fewshot_a"
# The few-shot probe run's contract: the module it runs, the protocol its summary names, and the set whose
# error the report reads.
PROBE_MODULE = "lerobot_omnid.diagnostics.position_extrapolation"
PROBE_PROTOCOL = "position_extrapolation"
PROBE_SET = "validation (id)"
"""Setting name of a model fine-tuned on camera A, evaluated with camera A in the ID setting."""
REPLAY = "_replay"
"""Suffix of a task's replay fine-tuning set: its camera-A few-shot episodes and as many training episodes
(env seeds from 0, replayed), both recorded with cameras A-E, merged; a per-frame column (``omnid-record
--hidden-cameras``) shows OmniD camera A alone in the first and B-E in the second."""
TRAIN_SEED = 1000  # lerobot-train --seed (LeRobot's default): same init RNG and batch order for every method
EVAL_SEED_STRIDE = 1000  # eval seed k runs env seeds k*1000 ... k*1000 + episodes - 1
FEWSHOT_SEED = 100_000  # first env seed of the few-shot recordings (training sets start at 0)
HELDOUT_SEED = 200_000  # first env seed of the held-out expert recordings of the open-loop diagnostic
OFFLINE_OUTPUT = "offline_eval.json"  # written by omnid-offline-eval into an offline run's folder


@dataclass(frozen=True)
class BenchmarkProfile:
    """Sizes of one benchmark run. ``tasks=None`` means every task in ``gym_omnid.constants.TASKS``."""

    name: str
    methods: tuple[str, ...]
    tasks: tuple[str, ...] | None
    episodes: int  # expert episodes per training set
    fewshot_episodes: int  # camera-A episodes per few-shot set
    image_size: int  # square images, pixels
    steps: int  # training steps, every method and task
    finetune_steps: int
    batch_size: int
    eval_episodes: int  # per setting and eval seed
    eval_batch_size: int  # envs run at once by each lerobot-eval (--eval.batch_size)
    heldout_episodes: int  # held-out expert episodes per task-0 setting for the open-loop action error
    eval_seeds: tuple[int, ...]
    episode_length: int  # time limit of an evaluation episode, env steps (10 per second)
    settings: tuple[str, ...]  # evaluation settings of task 0 (every task with every_task); others: ID
    control_settings: tuple[str, ...]  # of those settings, the ones in which the controls are evaluated
    train_seeds: tuple[int, ...]  # lerobot-train --seed of each repetition of the training runs
    fewshot: bool
    ablations: bool
    device: str
    num_workers: int
    small: bool  # CPU-sized models and a short-run optimiser schedule
    fuse_last_step_only: bool = False  # OmniD encodes only the last observation step (cheaper steps)
    task_steps: tuple[tuple[str, int], ...] = ()  # (task, training steps) where not ``steps``: task sizing
    every_task: bool = False  # ``settings`` and the controls on every task, not on task 0 only
    multitask: bool = False  # also one OmniD and one DP trained on every task together (MULTITASK_METHODS)
    controls: tuple[str, ...] = CONTROLS  # the controls planned, of each method's (``method_controls``)
    variants: tuple[Variant, ...] = ()  # methods with other options on task 0, each its own table row
    fewshot_recipes: tuple[FewshotRecipe, ...] = (PAPER_RECIPE,)  # with ``fewshot``: how each model is tuned
    fewshot_probe: bool = False  # with ``fewshot``: a position probe of every fine-tuned task-0 model

    def __post_init__(self) -> None:
        """Variants: distinct names that are no method's or other model's, of a method the profile trains.
        Few-shot recipes: distinct names, each starting from the method as trained or an OmniD variant; a
        zero-shot one (0 steps) with nothing else to follow."""
        names = [v.name for v in self.variants]
        for v in self.variants:
            if v.method not in self.methods or v.name in LABELS or names.count(v.name) > 1:
                raise ValueError(
                    f"variants: expected distinct new names of methods among {list(self.methods)}, got "
                    f"{v.name!r} of {v.method!r}"
                )
        if set(self.control_settings) & set(RIG_SETTINGS):
            raise ValueError(
                f"control_settings: expected none of {list(RIG_SETTINGS)} (a control's calibration is "
                f"static, a moved rig's per frame), got {list(self.control_settings)}"
            )
        recipes = [r.name for r in self.fewshot_recipes]
        starts = ["", *(v.name for v in self.variants if v.method == "omnid")]
        for r in self.fewshot_recipes:
            if recipes.count(r.name) > 1 or r.start not in starts:
                raise ValueError(
                    f"fewshot_recipes: expected distinct names, each starting from one of {starts}, got "
                    f"{r.name!r} starting from {r.start!r}"
                )
            if r.steps == 0 and (r.lr is not None or r.frozen or r.replay):
                raise ValueError(
                    f"fewshot_recipes: {r.name!r}: expected a zero-shot recipe (steps 0) to have no learning "
                    f"rate, frozen parts or replay, got lr {r.lr}, frozen {r.frozen}, replay {r.replay}"
                )

    @property
    def labels(self) -> dict[str, str]:
        """The table label of every model: the methods', the variants' and the few-shot recipes'."""
        recipes = {
            fewshot_model(m, r): f"{LABELS[m]} {r.label}"
            for m in self.methods
            for r in self.fewshot_recipes
            if r.name
        }
        return {**LABELS, **{v.name: v.label for v in self.variants}, **recipes}

    def method_recipes(self, method: str) -> tuple[FewshotRecipe, ...]:
        """The few-shot recipes as ``method`` follows them (:meth:`FewshotRecipe.for_method`), a recipe
        that would repeat an earlier one's fine-tuning left out."""
        found: dict[tuple, FewshotRecipe] = {}
        for recipe in self.fewshot_recipes:
            own = recipe.for_method(method)
            found.setdefault(dataclasses.astuple(dataclasses.replace(own, name="", label="")), own)
        return tuple(found.values())

    def for_task(self, task: str) -> BenchmarkProfile:
        """This profile with ``task``'s training steps (``task_steps``), which size every method's run on
        it (VQ-BeT's tokeniser phase too)."""
        return dataclasses.replace(self, steps=dict(self.task_steps).get(task, self.steps))

    def task_settings(self, task: str) -> tuple[str, ...]:
        """The settings ``task`` is evaluated in: ``settings`` on task 0 (on every task with
        ``every_task``), ID on the others."""
        return self.settings if task == TASK0 or self.every_task else ("id",)

    def task_controls(self, method: str, task: str) -> tuple[str, ...]:
        """The controls of ``method``'s model of ``task``: on task 0 (every task with ``every_task``),
        those of ``method_controls`` that the profile plans."""
        if task != TASK0 and not self.every_task:
            return ()
        return tuple(c for c in method_controls(method) if c in self.controls)


NEW_CAMERA_RECIPE = FewshotRecipe("long", "1000 steps", 1000)
"""The new-camera validation's selection (docs/results/new_camera_validation_cpu2.json): 1000 fine-tuning
steps at the training learning rate, every weight trained."""
ZERO_SHOT_RECIPE = FewshotRecipe("zero_shot", "zero-shot", 0)
"""No fine-tuning: each task-0 model on camera A as it is (:func:`zero_shot_options`)."""

# mini uses 64 px images: ResNet-18 forward+backward on a batch's 64 images takes 2.7 s at 96 px on some
# 2-core machines, which would put the profile over its 2-hour budget; 64 px has 0.44x the pixels.
# fmt: off
MINI = BenchmarkProfile(
    name="mini", methods=("omnid", "diffusion"), tasks=(TASK0,), episodes=50, fewshot_episodes=10,
    image_size=64, steps=1000, finetune_steps=200, batch_size=8, eval_episodes=10, eval_batch_size=5,
    heldout_episodes=3,
    eval_seeds=(1,), episode_length=200, settings=SETTINGS, control_settings=("id",),
    train_seeds=(TRAIN_SEED,), fewshot=False, ablations=False, device="cpu", num_workers=2, small=True,
)
PROFILES = {
    "mini": MINI,
    # Few-shot on camera A on a CPU: mini's task-0 models (same data, steps and seeds, so run it with mini's
    # --out to reuse them) fine-tuned on 10 camera-A episodes of select_apple and of select_chemistry_tube.
    "mini-fewshot": dataclasses.replace(
        MINI, name="mini-fewshot", heldout_episodes=0, settings=("id",), fewshot=True
    ),
    # One large GPU in about 8 minutes (not yet measured on one): mini's model sizes with 3x the steps and
    # 4x the batch (OmniD encoding the last observation step only), ID, one unseen table and one position
    # band, 30 episodes per cell with the controls.
    "gpu8": BenchmarkProfile(
        name="gpu8", methods=("omnid", "diffusion"), tasks=(TASK0,), episodes=50, fewshot_episodes=10,
        image_size=64, steps=3000, finetune_steps=200, batch_size=32, eval_episodes=30, eval_batch_size=10,
        heldout_episodes=0, eval_seeds=(1,), episode_length=200, settings=("id", "ood2", "position_band_2"),
        control_settings=("id",), train_seeds=(TRAIN_SEED,), fewshot=False, ablations=False, device="cuda",
        num_workers=8, small=True, fuse_last_step_only=True,
    ),
    # The six-task table on a CPU: mini's data and models (OmniD encoding the last observation step only,
    # as validated), every method, one unseen table, the controls on every task, two disjoint ranges of
    # 15 test episodes per cell; trained for each task's sized steps (``--task-steps``); then OmniD and DP
    # trained on every task together for the steps of the six single-task models together.
    "six-tasks": dataclasses.replace(
        MINI, name="six-tasks", methods=METHODS, tasks=None, heldout_episodes=0, eval_episodes=15,
        eval_seeds=(1, 2), settings=("id", "ood2"), every_task=True, controls=("blind", "scrambled"),
        fuse_last_step_only=True, multitask=True,
    ),
    # Validation of what extends the position curve (docs/benchmark.md#position-its-protocol): OmniD and DP
    # trained as for six-tasks (mini's options, OmniD encoding the last step only) and their
    # POSITION_VARIANTS, in ID and the four bands on validation env seeds.
    "position-validation": dataclasses.replace(
        MINI, name="position-validation", heldout_episodes=0, eval_episodes=10, eval_seeds=(80,),
        settings=("id", *BANDS), control_settings=(), controls=(), fuse_last_step_only=True,
        variants=POSITION_VARIANTS,
    ),
    # Validation of what keeps OmniD's success on a moved rig (docs/benchmark.md#moved-rigs-its-protocol):
    # OmniD and DP as for position-validation (run it with that --out to reuse both) and RIG_VARIANTS, in
    # ID and on the two unseen rigs, each with its true calibration, on validation env seeds.
    "rigs-validation": dataclasses.replace(
        MINI, name="rigs-validation", heldout_episodes=0, eval_episodes=10, eval_seeds=(81,),
        settings=("id", *RIG_SETTINGS), control_settings=(), controls=(), fuse_last_step_only=True,
        variants=RIG_VARIANTS,
    ),
    # The new camera's test (docs/benchmark.md#a-new-camera-its-protocol): mini-fewshot with the recipe the
    # validation selected (NEW_CAMERA_RECIPE) beside the paper's and zero-shot, two training seeds, two
    # disjoint ranges of 15 test episodes per cell and the probe; run with the validation's --out to reuse
    # its runs. The B-E models' controls are mini's (measured there): only the camera-A models' blind
    # controls run.
    "new-camera": dataclasses.replace(
        MINI, name="new-camera", heldout_episodes=0, settings=("id",), control_settings=(), fewshot=True,
        eval_episodes=15,
        eval_seeds=(1, 2), train_seeds=(TRAIN_SEED, TRAIN_SEED + 1),
        fewshot_recipes=(PAPER_RECIPE, NEW_CAMERA_RECIPE, ZERO_SHOT_RECIPE), fewshot_probe=True,
    ),
    "paper": BenchmarkProfile(
        name="paper", methods=METHODS, tasks=None, episodes=50, fewshot_episodes=10, image_size=128,
        steps=100_000, finetune_steps=5000, batch_size=16, eval_episodes=50, eval_batch_size=10,
        heldout_episodes=20,
        eval_seeds=(1, 2, 3, 4), episode_length=200, settings=SETTINGS,
        control_settings=("id", "position_ood"), train_seeds=(TRAIN_SEED,), fewshot=True, ablations=True,
        device="cuda", num_workers=8, small=False,
    ),
}
# fmt: on


def available_tasks() -> tuple[str, ...]:
    """The benchmark's tasks, read when called: a task added to gym_omnid is picked up."""
    return tuple(gym_omnid.constants.TASKS)


def heldout_dataset(task: str, setting: str) -> str:
    """Name of the held-out expert recording (cameras B-E) of ``task`` in ``setting``."""
    return f"{task}_bcde_heldout_{setting}"


def setting_env(setting: str) -> tuple[str, str]:
    """(layout, background) of an evaluation setting."""
    if setting in ("id", FEWSHOT, *RIG_SETTINGS):
        return "id", "id"
    if setting == "position_ood" or setting in BANDS:
        return setting, "id"
    if setting in BACKGROUND_OODS:
        return "id", setting
    raise ValueError(
        f"setting: expected id, {FEWSHOT}, position_ood or one of "
        f"{[*BACKGROUND_OODS, *BANDS, *RIG_SETTINGS]}, got {setting!r}"
    )


def rig_options(setting: str, method: str, cameras: Sequence[str]) -> list[str]:
    """``lerobot-eval`` options of a moved-rig setting (none for the others): the env's rig and, for
    OmniD, its true calibration read from every frame (a checkpoint's static one is the training rig's)."""
    if setting not in RIG_SETTINGS:
        return []
    options = [f"--env.rig={setting.removeprefix('rig_')}"]
    return options + (frame_calibration_options(cameras) if method == "omnid" else [])


def frame_calibration_options(cameras: Sequence[str]) -> list[str]:
    """``lerobot-eval`` options with which OmniD reads ``cameras``' true calibration from every frame."""
    keys = json_list([image_key(c) for c in cameras])
    return ["--env.per_frame_calibration=true", f"--policy.frame_calibration={keys}"]


def zero_shot_options(method: str) -> list[str]:
    """``lerobot-eval`` options of a zero-shot evaluation on camera A: OmniD's B-E model takes camera A
    alone, with its true calibration read from every frame (the checkpoint holds none of it); the others'
    camera-A copy needs none."""
    if method != "omnid":
        return []
    return ["--policy.cameras=" + json_list(CAMERA_A), *frame_calibration_options(CAMERA_A)]


def control_setting(setting: str, control: str, control_settings: Sequence[str]) -> str | None:
    """The setting whose ``control`` evaluation controls ``setting``, or None: its own where it is evaluated;
    for a background OOD the ID one's under the blind control, which is the same evaluation (same env seeds,
    hence the same layouts, and a blind policy sees no table)."""
    if setting in control_settings:
        return setting
    if control == "blind" and setting in BACKGROUND_OODS and "id" in control_settings:
        return "id"
    return None


def seed_folder(out: Path, train_seed: int) -> tuple[Path, str]:
    """Folder and run-name prefix of one training seed's runs: ``out`` itself for ``TRAIN_SEED`` (the folders
    of the runs made before training seeds were a dimension), ``out/train_seed<seed>/`` for the others."""
    if train_seed == TRAIN_SEED:
        return out, ""
    return out / f"train_seed{train_seed}", f"train_seed{train_seed}/"


def build_plan(p: BenchmarkProfile, out: Path, tasks: Sequence[str]) -> list[Run]:
    """Every run of the benchmark: the recordings, then per training seed (:func:`seed_folder`) the training
    runs, each model's evaluations right after its training (so results come early), its controls and its
    open-loop diagnostic."""
    runs: list[Run] = []

    def record(
        name: str,
        task: str,
        cameras: Sequence[str],
        episodes: int,
        seed: int,
        setting: str = "id",
        onehot: bool = False,
    ) -> None:
        root = out / "data" / name
        layout, background = setting_env(setting)
        cmd = record_command(task, episodes, cameras, p.image_size, root, seed, layout, background)
        cmd += ["--task-onehot"] if onehot else []
        runs.append(Run(f"record/{name}", "record", tuple(cmd), root, episodes=episodes))

    for task in tasks:
        record(f"{task}_bcde", task, TRAIN_CAMERAS, p.episodes, seed=0)
    if multitask(p, tasks):  # the same episodes, with the task one-hot, merged into one dataset
        for task in tasks:
            record(f"{task}_bcde_onehot", task, TRAIN_CAMERAS, p.episodes, seed=0, onehot=True)
        parts = [f"{task}_bcde_onehot" for task in tasks]
        root = out / "data" / MULTITASK_DATASET
        cmd = merge_command([out / "data" / part for part in parts], root)
        runs.append(
            Run(f"merge/{MULTITASK_DATASET}", "merge", tuple(cmd), root, tuple(f"record/{x}" for x in parts))
        )
    if p.ablations and TASK0 in tasks:
        record(f"{TASK0}_a", TASK0, CAMERA_A, p.episodes, seed=0)  # the B-E set's episodes, seen by A
    fewshot_tasks = (TASK0, TASK1) if p.fewshot and TASK0 in tasks else ()
    for task in fewshot_tasks:
        record(f"{task}_a_fewshot", task, CAMERA_A, p.fewshot_episodes, seed=FEWSHOT_SEED)
        if "omnid" in p.methods and any(r.replay for r in p.fewshot_recipes):
            runs += replay_runs(p, out, task)
    for setting in heldout_settings(p, tasks):
        record(
            heldout_dataset(TASK0, setting), TASK0, TRAIN_CAMERAS, p.heldout_episodes, HELDOUT_SEED, setting
        )
    for train_seed in p.train_seeds:
        runs += plan_models(p, out, tasks, train_seed, fewshot_tasks)
    return plan(runs, out)


def replay_runs(p: BenchmarkProfile, out: Path, task: str) -> list[Run]:
    """The recordings and the merge of ``task``'s replay fine-tuning set (``REPLAY``)."""
    runs, parts = [], []
    every = (*CAMERA_A, *TRAIN_CAMERAS)
    for part, seed, hidden in (("a", FEWSHOT_SEED, TRAIN_CAMERAS), ("bcde", 0, CAMERA_A)):
        root = out / "data" / f"{task}_a_fewshot{REPLAY}_{part}"
        cmd = record_command(task, p.fewshot_episodes, every, p.image_size, root, seed=seed)
        cmd += ["--hidden-cameras", ",".join(hidden)]
        runs.append(Run(f"record/{root.name}", "record", tuple(cmd), root, episodes=p.fewshot_episodes))
        parts.append(root)
    merged = out / "data" / f"{task}_a_fewshot{REPLAY}"
    needs = tuple(f"record/{part.name}" for part in parts)
    runs.append(Run(f"merge/{merged.name}", "merge", tuple(merge_command(parts, merged)), merged, needs))
    return runs


def multitask(p: BenchmarkProfile, tasks: Sequence[str]) -> bool:
    """Whether the plan has the multi-task models: asked for, with every task of the benchmark planned (a
    model of some tasks only would be another model under the same name) and a method that has one."""
    together = set(tasks) == set(available_tasks()) and len(tasks) > 1
    return p.multitask and together and any(m in p.methods for m in MULTITASK_METHODS)


def multitask_steps(p: BenchmarkProfile, tasks: Sequence[str]) -> int:
    """Training steps of a multi-task model: those of the single-task models of ``tasks`` together."""
    return sum(p.for_task(task).steps for task in tasks)


def train_folder(p: BenchmarkProfile, steps: int) -> str:
    """Folder of the models trained from scratch: ``train`` at the profile's steps, ``train_steps<n>`` for a
    task sized to other steps (the task sizing's own folder for that budget, so its run is reused)."""
    return "train" if steps == p.steps else f"train_steps{steps}"


def heldout_settings(p: BenchmarkProfile, tasks: Sequence[str]) -> tuple[str, ...]:
    """Task-0 settings of the open-loop diagnostic: every setting but the graded bands (the position-OOD
    band holds the first two; the curve is measured by success)."""
    if not p.heldout_episodes or TASK0 not in tasks:
        return ()
    return tuple(s for s in p.settings if s not in BANDS)


def plan_models(
    p: BenchmarkProfile, out: Path, tasks: Sequence[str], train_seed: int, fewshot_tasks: Sequence[str]
) -> list[Run]:
    """The runs of one training seed: training, evaluations, controls, fine-tuning, open-loop diagnostic."""
    root, prefix = seed_folder(out, train_seed)
    runs: list[Run] = []

    def train(
        folder: str, model: str, task: str, dataset: str, flags: list[str], steps: int, needs=()
    ) -> Run:
        """Train ``model`` on ``dataset`` (made by its "record" run, or a "merge")."""
        output = root / folder / model / task
        data = out / "data" / dataset
        cmd = train_command(data, output, flags, steps, p.batch_size, p.num_workers, seed=train_seed)
        name = f"{prefix}{folder}/{model}/{task}"
        merged = dataset == MULTITASK_DATASET or dataset.endswith(REPLAY)
        made_by = f"merge/{dataset}" if merged else f"record/{dataset}"
        run = Run(name, "train", tuple(cmd), output, (made_by, *needs), train_seed=train_seed)
        runs.append(run)
        return run

    def evaluate(
        trained: Run,
        model: str,
        task: str,
        settings: Sequence[str],
        cameras: Sequence[str],
        control: str = "",
        control_options: Sequence[str] = (),
        needs: Sequence[str] = (),
        method: str = "",
        checkpoint: Path | None = None,
    ) -> None:
        """Evaluate ``trained`` (its ``checkpoint``, by default the one it trained) as ``model`` in
        ``settings``; a moved rig's needs ``method``."""
        folder = f"eval_{control}" if control else "eval"
        for setting in settings:
            layout, background = setting_env(setting)
            for k in p.eval_seeds:
                output = root / folder / model / task / setting / f"seed{k}"
                cmd = eval_command(
                    checkpoint or trained.output / CHECKPOINT_SUBDIR,
                    output,
                    task,
                    layout,
                    cameras,
                    p.image_size,
                    p.eval_episodes,
                    p.device,
                    background,
                    seed=k * EVAL_SEED_STRIDE,
                    extra=(
                        f"--env.episode_length={p.episode_length}",
                        *control_options,
                        *rig_options(setting, method, cameras),
                    ),
                    batch_size=min(p.eval_batch_size, p.eval_episodes),
                )
                name = f"{prefix}{folder}/{model}/{task}/{setting}/seed{k}"
                result = (model, task, setting)
                run = Run(name, "eval", tuple(cmd), output, (trained.name, *needs), 0, result, k, train_seed)
                runs.append(dataclasses.replace(run, control=control))

    def controls(
        trained: Run,
        method: str,
        task: str,
        settings: Sequence[str],
        cameras: Sequence[str],
        kinds: Sequence[str],
        model: str = "",
        key: str = "",
        options: Sequence[str] = (),
    ) -> None:
        """The ``kinds`` of controls of ``trained`` (a ``method`` checkpoint) on ``task`` in ``settings``;
        ``model`` ("" for the checkpoint trained from scratch, else e.g. ``FEWSHOT``) names its files;
        ``key`` is the model of its table cells (default ``method``), ``options`` go to every evaluation."""
        key = key or method
        for control in kinds if settings else ():
            needs: tuple[str, ...] = ()
            where = f"{model}/{control}" if model else control
            calibration_file = root / "controls" / key / task / f"{where}.json"
            if method == "omnid":
                cmd = control_calibration_command(
                    trained.output / CHECKPOINT_SUBDIR, control, calibration_file
                )
                name = f"{prefix}calibration/{key}/{task}/{where}"
                run = Run(
                    name, "calibration", tuple(cmd), calibration_file, (trained.name,), train_seed=train_seed
                )
                runs.append(run)
                needs = (run.name,)
            flags = [f for f, _ in control_flags(method, control, cameras, calibration_file)]
            evaluate(trained, key, task, settings, cameras, control, [*flags, *options], needs)

    def offline(trained: Run, model: str, task: str, settings: Sequence[str]) -> None:
        """Open-loop action error of ``trained`` on the held-out expert episodes of each setting."""
        for setting in settings:
            dataset = heldout_dataset(task, setting)
            output = root / "offline" / model / task / setting
            cmd = [str(BIN / "omnid-offline-eval"), "--checkpoint", str(trained.output / CHECKPOINT_SUBDIR)]
            cmd += ["--root", str(out / "data" / dataset), "--episodes", str(p.heldout_episodes)]
            cmd += ["--device", p.device]
            cmd += ["--out", str(output / OFFLINE_OUTPUT)]
            needs = (trained.name, f"record/{dataset}")
            name = f"{prefix}offline/{model}/{task}/{setting}"
            runs.append(
                Run(name, "offline", tuple(cmd), output, needs, 0, (model, task, setting), None, train_seed)
            )

    def common(method: str) -> list[str]:
        return [f"--policy.type={method}", f"--policy.device={p.device}", "--policy.push_to_hub=false"]

    for task in tasks:
        sized = p.for_task(task)
        folder = train_folder(p, sized.steps)
        for method in p.methods:
            flags = [f for f, _ in method_flags(method, sized)]
            trained = train(folder, method, task, f"{task}_bcde", [*common(method), *flags], sized.steps)
            cameras = VQBET_CAMERA if method == "vqbet" else TRAIN_CAMERAS
            settings = p.task_settings(task)
            evaluate(trained, method, task, settings, cameras, method=method)
            controlled = [s for s in p.control_settings if s in settings]
            controls(trained, method, task, controlled, cameras, p.task_controls(method, task))
            if task == TASK0:
                offline(trained, method, task, heldout_settings(p, tasks))
    if multitask(p, tasks):
        steps = multitask_steps(p, tasks)
        sized = dataclasses.replace(p, steps=steps)
        onehot = ("--env.task_onehot=true",)
        for method in (m for m in MULTITASK_METHODS if m in p.methods):
            flags = [*common(method), *(f for f, _ in method_flags(method, sized))]
            trained = train("train_multitask", method, "all_tasks", MULTITASK_DATASET, flags, steps)
            key = method + MULTITASK
            for task in tasks:
                evaluate(trained, key, task, ("id",), TRAIN_CAMERAS, control_options=onehot)
                kinds = tuple(c for c in p.task_controls(method, task) if c == "blind")
                controls(trained, method, task, ("id",), TRAIN_CAMERAS, kinds, key=key, options=onehot)
    for variant in p.variants if TASK0 in tasks else ():
        sized = p.for_task(TASK0)
        flags = [*common(variant.method), *(f for f, _ in variant_flags(variant, sized))]
        trained = train(
            train_folder(p, sized.steps), variant.name, TASK0, f"{TASK0}_bcde", flags, sized.steps
        )
        cameras = VQBET_CAMERA if variant.method == "vqbet" else TRAIN_CAMERAS
        settings = p.task_settings(TASK0)
        evaluate(trained, variant.name, TASK0, settings, cameras, method=variant.method)
        controlled = [s for s in p.control_settings if s in settings]
        kinds = p.task_controls(variant.method, TASK0)
        controls(trained, variant.method, TASK0, controlled, cameras, kinds, key=variant.name)
    if p.ablations and TASK0 in tasks:
        for name in ABLATIONS:
            sized = p.for_task(TASK0)
            flags = [f for f, _ in ablation_flags(name, sized)]
            dataset = f"{TASK0}_a" if name == "omnid_cam_a" else f"{TASK0}_bcde"
            trained = train(
                train_folder(p, sized.steps), name, TASK0, dataset, [*common("omnid"), *flags], sized.steps
            )
            evaluate(trained, name, TASK0, ("id",), CAMERA_A if name == "omnid_cam_a" else TRAIN_CAMERAS)
    task0_folder = train_folder(p, p.for_task(TASK0).steps)
    tuned_task0: list[Run] = []
    for method in p.methods if fewshot_tasks else ():
        if method != "omnid":  # a copy whose image input is camera A
            src = root / task0_folder / method / TASK0 / CHECKPOINT_SUBDIR
            copy = root / "finetune" / method / "start_cam_a"
            cmd = [sys.executable, "-m", "lerobot_omnid.benchmark.checkpoint_cameras", "--src", str(src)]
            cmd += ["--dst", str(copy), "--cameras", ",".join(CAMERA_A)]
            name = f"{prefix}prepare/{method}/cam_a"
            needs = (f"{prefix}{task0_folder}/{method}/{TASK0}",)
            prepared = Run(name, "prepare", tuple(cmd), copy, needs, train_seed=train_seed)
            runs.append(prepared)
        for recipe in p.method_recipes(method):
            model = fewshot_model(method, recipe)
            if method != "omnid":
                start, start_run = copy, name
            else:
                start_run = f"{prefix}{task0_folder}/{recipe.start or method}/{TASK0}"
                start = root / task0_folder / (recipe.start or method) / TASK0 / CHECKPOINT_SUBDIR
            if recipe.steps == 0:  # zero-shot: the start model as it is, on its own task only
                started = prepared if method != "omnid" else next(r for r in runs if r.name == start_run)
                options = zero_shot_options(method)
                # blind: black images (OmniD's turned-away control file would hold the B-E cameras)
                black = [f"--env.blackout_cameras=[{','.join(CAMERA_A)}]", *options]
                for control, flags in (("", options), ("blind", black)):
                    evaluate(started, model, TASK0, (FEWSHOT,), CAMERA_A, control, flags, checkpoint=start)
                continue
            for task in fewshot_tasks:
                flags = [f"--policy.path={start}", f"--policy.device={p.device}"]
                flags += ["--policy.push_to_hub=false", *(f for f, _ in recipe_flags(method, recipe))]
                dataset = f"{task}_a_fewshot" + (REPLAY if recipe.replay else "")
                steps = recipe.steps or p.finetune_steps
                tuned = train("finetune", model, task, dataset, flags, steps, needs=(start_run,))
                tuned_task0 += [tuned] if task == TASK0 else []
                evaluate(tuned, model, task, (FEWSHOT,), CAMERA_A)
                # One camera: blind only (no other camera's calibration to permute).
                controls(tuned, method, task, (FEWSHOT,), CAMERA_A, ("blind",), model=FEWSHOT, key=model)
    if p.fewshot_probe and tuned_task0:
        runs.append(fewshot_probe(p, out, root, prefix, tuned_task0, train_seed))
    return runs


def fewshot_probe(
    p: BenchmarkProfile, out: Path, root: Path, prefix: str, tuned: Sequence[Run], train_seed: int
) -> Run:
    """Where each fine-tuned task-0 model's image condition places the apple: the linear probe of
    ``lerobot_omnid.diagnostics.position_extrapolation``, fitted on the camera-A episodes they were tuned
    on, its error measured on fresh camera-A expert episodes."""
    output = root / "probe" / FEWSHOT
    data = f"{TASK0}_a_fewshot"
    cmd = [sys.executable, "-m", PROBE_MODULE, "--out", str(output)]
    cmd += ["--train-root", str(out / "data" / data), "--device", p.device]
    for run in tuned:
        cmd += ["--checkpoint", f"{run.output.parent.name}={run.output / CHECKPOINT_SUBDIR}"]
    needs = (f"record/{data}", *(run.name for run in tuned))
    return Run(f"{prefix}probe/{FEWSHOT}", "probe", tuple(cmd), output, needs, train_seed=train_seed)
