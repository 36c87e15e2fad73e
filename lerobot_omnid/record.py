"""``omnid-record``: run the scripted experts of the OmniD benchmark and write a LeRobot dataset.

Each camera becomes a video feature ``observation.images.<cam>``, and its calibration
(:class:`~lerobot_omnid.calibration.schema.CameraCalibration`) is written in every frame, as the columns
``observation.extrinsics.<cam>`` and ``observation.intrinsics.<cam>``
(:mod:`lerobot_omnid.calibration.frame_columns`); the image features' ``info`` holds no calibration.
The feature schema is then the same for every rig (``--rig``), so datasets recorded with different rigs,
today's and next month's, merge with ``lerobot-edit-dataset --operation.type merge``, each episode keeping
its own rig's calibration. ``observation.state`` and ``action`` carry the env's state and action names;
every frame's ``task`` is the env's language instruction. Only successful expert episodes are kept.
Attempt ``i`` (counting failed ones) resets the env with seed ``seed + i``, so the same arguments give the
same data.

``--static-calibration`` writes the older form instead: each camera's calibration once, in its image
feature's ``info["calibration"]``. Such datasets merge only with datasets of the same rig, but a
calibration file replaces only this form (``--policy.calibration_path``: the benchmark's blind,
scrambled and perturbed controls, ``omnid-robustness``), so the benchmark records it. The wrist camera
(``cam_wrist``) moves, so it is recorded only per frame. ``--per-frame-calibration`` names the default
(it was opt-in before and is still accepted); the two flags exclude each other.

``--task-onehot`` adds the column ``observation.environment_state``: the task as a one-hot over
``gym_omnid.constants.TASKS`` (names: the task names), in every frame, as the env observes it. Its feature is
the same for every task, so datasets of different tasks recorded with it merge into one multi-task dataset
on which a policy that reads ``observation.environment_state`` (OmniD, LeRobot's DP and ACT) learns which
task it is asked for; evaluate it with ``--env.task_onehot=true``.

``--hidden-cameras`` adds the column ``observation.camera_visible`` (:mod:`lerobot_omnid.camera_visibility`):
per recorded camera, 1.0 if the episodes are meant to show it, 0.0 if they hide it. Every camera is still
recorded with its real images; OmniD leaves the hidden ones out of its fusion. The feature does not depend on
which cameras are hidden, so a dataset of new-camera episodes (``--hidden-cameras cam_b,cam_c,cam_d,cam_e``)
and one of replayed training-camera episodes (``--hidden-cameras cam_a``), both recorded with the five
cameras, merge into one fine-tuning set. ``--hidden-cameras ''`` writes the column with every camera visible,
for episodes that show them all in such a merge.

Example::

    MUJOCO_GL=egl omnid-record --task select_apple --episodes 50 --root data/omnid_select_apple

``--suite metaworld`` records a MetaWorld v3 task (:mod:`gym_omnid.metaworld_suite`, the optional dependency
``metaworld``) with MetaWorld's scripted policy as the expert, in the same layout: the cameras ``corner``,
``corner2``, ``corner3`` and the hand camera ``behindGripper`` (calibrated per frame), MetaWorld's state
and 4-D action::

    MUJOCO_GL=egl omnid-record --suite metaworld --task assembly-v3 --episodes 50

Ctrl-C stops after discarding the episode in progress and leaves a loadable dataset of the completed
episodes (press it again to abort at once).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gym_omnid import metaworld_suite
from gym_omnid.calibration import EXTRINSICS_OBS_PREFIX, INTRINSICS_OBS_PREFIX
from gym_omnid.constants import (
    ALL_CAMERAS,
    BACKGROUNDS,
    CAMERAS,
    DEFAULT_RIG,
    ENV_STATE_OBS_KEY,
    LAYOUTS,
    MAX_IMAGE_SIDE,
    RIGS,
    TASK_ONEHOT_NAMES,
    TASKS,
    WRIST_CAMERA,
)
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.utils.constants import ACTION, HF_LEROBOT_HOME, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE
from tqdm import tqdm

from lerobot_omnid.calibration.frame_columns import (
    calibration_column_features,
    extrinsics_key,
    intrinsics_key,
)
from lerobot_omnid.calibration.schema import CALIBRATION_INFO_KEY
from lerobot_omnid.camera_visibility import (
    CAMERA_VISIBLE_KEY,
    camera_visible_column,
    camera_visible_feature,
    check_hidden_cameras,
)
from lerobot_omnid.cli import check_positive_int, positive_int
from lerobot_omnid.env_config import OmniDEnvConfig, calibration_dict, validate_cameras, validate_image_size
from lerobot_omnid.env_config_metaworld import OmniDMetaWorldEnvConfig

SUITES = ("omnid", "metaworld")
"""Env suites ``--suite`` records: our benchmark (``gym_omnid``), MetaWorld v3 (``metaworld_suite``)."""

ROBOT_TYPE = "omnid_sim_arm"
"""``robot_type`` written to the dataset metadata (the omnid suite)."""

ROBOT_TYPES = {"omnid": ROBOT_TYPE, "metaworld": "metaworld_sawyer"}
"""``robot_type`` written to the dataset metadata, per suite."""

SUITE_TASKS = {"omnid": TASKS, "metaworld": metaworld_suite.TASKS}
SUITE_CAMERAS = {"omnid": ALL_CAMERAS, "metaworld": metaworld_suite.ALL_CAMERAS}
DEFAULT_CAMERAS = {"omnid": CAMERAS, "metaworld": metaworld_suite.DEFAULT_CAMERAS}
MOVING_CAMERAS = {"omnid": (WRIST_CAMERA,), "metaworld": metaworld_suite.HAND_CAMERAS}

EXIT_INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT), as shells report it."""

IMAGE_NAMES = ["height", "width", "channels"]
"""``names`` of the video features' dimensions."""


@dataclass(frozen=True)
class RecordSummary:
    """What one recording produced.

    Args:
        root: Dataset directory (removed again when no episode was saved).
        repo_id: Dataset repo id.
        requested: Number of episodes asked for.
        episodes: Successful episodes saved.
        attempts: Expert episodes run, failed and interrupted ones included.
        frames: Frames saved.
        wall_time_s: Wall time of the whole recording, seconds.
        interrupted: Whether Ctrl-C (KeyboardInterrupt) stopped the recording early.
    """

    root: Path
    repo_id: str
    requested: int
    episodes: int
    attempts: int
    frames: int
    wall_time_s: float
    interrupted: bool

    @property
    def complete(self) -> bool:
        return self.episodes == self.requested

    @property
    def frames_per_s(self) -> float:
        return self.frames / self.wall_time_s if self.wall_time_s > 0 else 0.0

    def line(self) -> str:
        where = str(self.root) if self.episodes else f"nothing kept ({self.root} removed)"
        return (
            f"{'Interrupted: ' if self.interrupted else ''}saved {self.episodes}/{self.requested} episodes "
            f"from {self.attempts} attempts, {self.frames} frames in {self.wall_time_s:.1f} s "
            f"({self.frames_per_s:.1f} frames/s): {where}"
        )


class _StopOnSigint:
    """Turn the first SIGINT into a stop request polled by the recording loop.

    The loop then ends at a frame boundary and saving or finalising is never cut in half. A second
    SIGINT raises KeyboardInterrupt at once. (Without streaming encoding, the encoder processes that
    LeRobot forks inherit the handler and finish their videos too.) Outside the main thread, where
    handlers cannot be set, this is a no-op and KeyboardInterrupt is handled by the loop's ``except``.
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous = None

    def _handle(self, signum, frame) -> None:
        self.requested = True
        signal.signal(signal.SIGINT, signal.default_int_handler)
        tqdm.write("Ctrl-C: stopping after discarding the episode in progress (press again to abort now).")

    @contextlib.contextmanager
    def installed(self) -> Iterator[_StopOnSigint]:
        if threading.current_thread() is not threading.main_thread():
            yield self
            return
        self._previous = signal.signal(signal.SIGINT, self._handle)
        try:
            yield self
        finally:
            signal.signal(signal.SIGINT, self._previous)


def check_wrist_calibration(
    cameras: Sequence[str], per_frame_calibration: bool, suite: str = "omnid"
) -> None:
    """Refuse a camera on the arm (gym_omnid's wrist camera, MetaWorld's hand cameras) with a static
    calibration: a moving camera has none."""
    moving = [cam for cam in cameras if cam in MOVING_CAMERAS[suite]]
    if moving and not per_frame_calibration:
        raise ValueError(
            f"cameras: {', '.join(moving)} moves with the arm, so its calibration changes every frame; "
            f"expected per-frame calibration with it (the default, per_frame_calibration=True), got "
            f"--static-calibration (per_frame_calibration=False) with cameras {list(cameras)}"
        )


def env_config(
    suite: str,
    task: str,
    cameras: Sequence[str] | None,
    layout: str,
    background: str,
    image_size: int,
    rig: str,
    per_frame_calibration: bool,
    episode_length: int | None,
    task_onehot: bool = False,
) -> OmniDEnvConfig | OmniDMetaWorldEnvConfig:
    """The env config of a recording (``cameras``/``episode_length`` None: the suite's defaults). MetaWorld
    has none of the omnid suite's variants: ``layout``, ``background`` and ``rig`` must be the defaults,
    ``task_onehot`` False."""
    if suite not in SUITES:
        raise ValueError(f"suite: expected one of {list(SUITES)}, got {suite!r}")
    cameras = list(DEFAULT_CAMERAS[suite] if cameras is None else cameras)
    extra = {} if episode_length is None else {"episode_length": episode_length}
    if suite == "omnid":
        return OmniDEnvConfig(
            task=task,
            cameras=cameras,
            layout=layout,
            background=background,
            image_size=image_size,
            rig=rig,
            per_frame_calibration=per_frame_calibration,
            task_onehot=task_onehot,
            **extra,
        )
    for name, value, default in (
        ("layout", layout, "id"),
        ("background", background, "id"),
        ("rig", rig, DEFAULT_RIG),
        ("task_onehot", task_onehot, False),
    ):
        if value != default:
            raise ValueError(
                f"{name}: the metaworld suite has no variants; expected {default!r}, got {value!r}"
            )
    return OmniDMetaWorldEnvConfig(
        task=task,
        cameras=cameras,
        image_size=image_size,
        per_frame_calibration=per_frame_calibration,
        **extra,
    )


def make_expert(suite: str, env: gym.Env) -> Any:
    """The scripted expert of the episode just reset in ``env``: an object whose ``act()`` gives the next
    action (gym_omnid's waypoint experts, MetaWorld's scripted policies)."""
    if suite == "metaworld":
        from gym_omnid.metaworld_suite.experts import make_expert as make_metaworld_expert

        return make_metaworld_expert(env.unwrapped)
    from gym_omnid.experts import make_expert as make_omnid_expert

    return make_omnid_expert(env.unwrapped)


def dataset_features(
    env: gym.Env,
    cameras: Sequence[str],
    image_size: int,
    per_frame_calibration: bool = True,
    task_onehot: bool = False,
    camera_visible: bool = False,
) -> dict[str, dict]:
    """LeRobot feature spec of the recorded dataset: videos, named state and action, each camera's
    calibration (static in the video feature's info, or per frame as columns), with ``task_onehot`` the
    task one-hot ``observation.environment_state`` and with ``camera_visible`` the column
    ``observation.camera_visible`` over ``cameras``. Neither spec depends on the task or on which cameras
    are hidden (such datasets merge)."""
    unwrapped = env.unwrapped
    features: dict[str, dict] = {}
    for cam in cameras:
        key = f"{OBS_IMAGES}.{cam}"
        features[key] = {"dtype": "video", "shape": (image_size, image_size, 3), "names": IMAGE_NAMES}
        if not per_frame_calibration:
            features[key]["info"] = {CALIBRATION_INFO_KEY: calibration_dict(unwrapped, cam, key)}
    state_names = list(unwrapped.state_names)
    action_names = list(unwrapped.action_names)
    features[OBS_STATE] = {"dtype": "float32", "shape": (len(state_names),), "names": state_names}
    features[ACTION] = {"dtype": "float32", "shape": (len(action_names),), "names": action_names}
    if per_frame_calibration:
        features.update(calibration_column_features(cameras))
    if task_onehot:
        names = list(TASK_ONEHOT_NAMES)
        features[OBS_ENV_STATE] = {"dtype": "float32", "shape": (len(names),), "names": names}
    if camera_visible:
        features[CAMERA_VISIBLE_KEY] = camera_visible_feature(cameras)
    return features


def _check_root(root: Path) -> None:
    if root.exists():
        if not root.is_dir() or any(root.iterdir()):
            raise FileExistsError(
                f"--root: {root} already exists and is not an empty directory; refusing to overwrite it. "
                f"Choose a new directory or delete this one."
            )
        root.rmdir()  # LeRobot creates it itself and refuses an existing one


def _run_expert_episode(
    env: gym.Env,
    dataset: LeRobotDataset,
    cameras: Sequence[str],
    per_frame_calibration: bool,
    task_onehot: bool,
    camera_visible: np.ndarray | None,
    seed: int,
    stop: _StopOnSigint,
    expert_factory: Callable[[gym.Env], Any],
) -> bool | None:
    """Roll out the expert once, adding every frame (with the calibration the env observed it with, when
    ``per_frame_calibration``, its task one-hot, when ``task_onehot``, and the ``camera_visible`` column
    value, when given) to the dataset's episode buffer.

    Returns the episode's success, or None when a stop was requested before it ended.
    """
    obs, _ = env.reset(seed=seed)
    task = env.unwrapped.task_description
    expert = expert_factory(env)
    while True:
        action = np.asarray(expert.act(), dtype=np.float32)
        frame = {OBS_STATE: np.asarray(obs["agent_pos"], dtype=np.float32), ACTION: action, "task": task}
        for cam in cameras:
            frame[f"{OBS_IMAGES}.{cam}"] = obs["pixels"][cam]
            if per_frame_calibration:
                frame[extrinsics_key(cam)] = obs[f"{EXTRINSICS_OBS_PREFIX}{cam}"]
                frame[intrinsics_key(cam)] = obs[f"{INTRINSICS_OBS_PREFIX}{cam}"]
        if task_onehot:
            frame[OBS_ENV_STATE] = obs[ENV_STATE_OBS_KEY]
        if camera_visible is not None:
            frame[CAMERA_VISIBLE_KEY] = camera_visible
        dataset.add_frame(frame)
        obs, _, terminated, truncated, info = env.step(action)
        if stop.requested:
            return None
        if terminated or truncated:
            return bool(info.get("is_success", False))


def record_dataset(
    root: str | Path | None = None,
    *,
    suite: str = "omnid",
    task: str = "select_apple",
    episodes: int = 50,
    repo_id: str | None = None,
    cameras: Sequence[str] | None = None,
    layout: str = "id",
    background: str = "id",
    image_size: int = 128,
    rig: str = DEFAULT_RIG,
    per_frame_calibration: bool = True,
    task_onehot: bool = False,
    hidden_cameras: Sequence[str] | None = None,
    seed: int = 0,
    max_attempts: int | None = None,
    episode_length: int | None = None,
    streaming_encoding: bool = True,
    push_to_hub: bool = False,
    show_progress: bool = True,
) -> RecordSummary:
    """Record ``episodes`` successful expert episodes into a new LeRobot dataset at ``root``.

    Args:
        root: Output directory; must not exist or be empty. Default ``$HF_LEROBOT_HOME/<repo_id>``.
        suite: ``"omnid"`` (our benchmark) or ``"metaworld"`` (a MetaWorld v3 task: ``task`` one of
            ``gym_omnid.metaworld_suite.TASKS``, ``OmniDMetaWorldEnvConfig``; needs ``metaworld``).
        task, cameras, layout, background, image_size, rig: The env setting (see ``OmniDEnvConfig``);
            ``cameras`` None: the suite's default cameras.
        per_frame_calibration: Write every camera's calibration in every frame as the columns
            ``observation.extrinsics.<cam>`` / ``observation.intrinsics.<cam>`` (the default: datasets of
            different rigs merge, ``cam_wrist`` is possible); False writes it once in the image feature's
            info instead (the static form, ``--static-calibration``).
        task_onehot: Write the task as a one-hot over ``TASKS`` in every frame, the column
            ``observation.environment_state`` (omnid suite only), so that datasets of several tasks merge
            into one on which a policy learns which task it is asked for.
        hidden_cameras: Recorded cameras that the episodes are meant not to show (not all of them): every
            camera is recorded with its real images, and the column ``observation.camera_visible`` (0.0 for
            these, 1.0 for the others; :mod:`lerobot_omnid.camera_visibility`) tells OmniD to leave them out
            of its fusion. Empty: the column with every camera visible; None (default): no column.
        episodes: Successful episodes to save.
        repo_id: Dataset id; default ``local/omnid_<task>`` (``local/omnid_metaworld_<task>``).
        seed: Attempt ``i`` resets the env with ``seed + i``.
        max_attempts: Bound on expert episodes run (failed ones included); default
            ``2 * episodes + 10``. Reaching it ends the recording with fewer episodes (see the summary).
        episode_length: Time limit of one expert attempt, env steps; an attempt that reaches it fails.
            Default: the suite's episode length.
        streaming_encoding: Encode videos in threads while recording instead of LeRobot's default of
            writing PNG files and encoding them when the episode is saved (slower: bench_record.py).
        push_to_hub: Upload with LeRobot's ``push_to_hub`` when the recording completes.
        show_progress: Show a tqdm bar over episodes.
    """
    check_positive_int("episodes", episodes)
    max_attempts = 2 * episodes + 10 if max_attempts is None else max_attempts
    if isinstance(max_attempts, bool) or not isinstance(max_attempts, int) or max_attempts < episodes:
        raise ValueError(f"max_attempts: expected an int >= episodes ({episodes}), got {max_attempts!r}")
    cfg = env_config(
        suite,
        task,
        cameras,
        layout,
        background,
        image_size,
        rig,
        per_frame_calibration,
        episode_length,
        task_onehot,
    )
    check_wrist_calibration(cfg.cameras, per_frame_calibration, suite)
    camera_visible = None
    if hidden_cameras is not None:
        hidden = check_hidden_cameras("hidden_cameras", hidden_cameras, cfg.cameras)
        camera_visible = camera_visible_column(cfg.cameras, hidden)
    repo_id = repo_id or default_repo_id(suite, task)
    if push_to_hub and repo_id.startswith("local/"):
        raise ValueError(
            f"repo_id: pushing to the Hub needs your namespace "
            f"(e.g. <user>/{default_repo_id(suite, task).removeprefix('local/')}), got {repo_id!r}"
        )
    root = Path(root) if root is not None else HF_LEROBOT_HOME / repo_id
    _check_root(root)

    start = time.perf_counter()
    env = gym.make(cfg.gym_id, disable_env_checker=True, **cfg.gym_kwargs)
    stop = _StopOnSigint()
    dataset = None
    attempts = saved = 0
    interrupted = False
    try:
        features = dataset_features(
            env,
            cfg.cameras,
            cfg.image_size,
            cfg.per_frame_calibration,
            task_onehot,
            camera_visible is not None,
        )
        # Streaming: frames go to per-camera encoder threads (no PNG round trip). Their queues hold a
        # whole episode, so a frame is never dropped however slow the encoder is.
        dataset = LeRobotDataset.create(
            repo_id,
            fps=cfg.fps,
            root=root,
            features=features,
            robot_type=ROBOT_TYPES[suite],
            use_videos=True,
            video_backend="pyav",
            streaming_encoding=streaming_encoding,
            encoder_queue_maxsize=cfg.episode_length + 1,
        )
        with (
            stop.installed(),
            tqdm(total=episodes, unit="ep", desc=f"Recording {task}", disable=not show_progress) as bar,
        ):
            while saved < episodes and attempts < max_attempts:
                attempts += 1
                success = _run_expert_episode(
                    env,
                    dataset,
                    cfg.cameras,
                    cfg.per_frame_calibration,
                    task_onehot,
                    camera_visible,
                    seed + attempts - 1,
                    stop,
                    lambda env: make_expert(suite, env),
                )
                if success is None:
                    break
                if success:
                    dataset.save_episode()
                    saved += 1
                else:
                    dataset.clear_episode_buffer()
                frames_per_s = dataset.meta.total_frames / (time.perf_counter() - start)
                bar.set_postfix(
                    {"successes": f"{saved}/{attempts}", "fps": f"{frames_per_s:.1f}"}, refresh=False
                )
                if success:
                    bar.update(1)
                else:
                    bar.refresh()
    except KeyboardInterrupt:
        interrupted = True
    finally:
        interrupted = interrupted or stop.requested
        if dataset is not None:
            if dataset.writer.episode_buffer is not None:
                dataset.clear_episode_buffer()  # the episode in progress, if any (no-op otherwise)
            dataset.finalize()
        env.close()
        if saved == 0:
            shutil.rmtree(root, ignore_errors=True)  # an empty dataset cannot be loaded: leave nothing

    frames = dataset.meta.total_frames if saved else 0
    if saved and push_to_hub and not interrupted:
        dataset.push_to_hub()
    return RecordSummary(
        root=root,
        repo_id=repo_id,
        requested=episodes,
        episodes=saved,
        attempts=attempts,
        frames=frames,
        wall_time_s=time.perf_counter() - start,
        interrupted=interrupted,
    )


def default_repo_id(suite: str, task: str) -> str:
    """``local/omnid_<task>`` (``local/omnid_metaworld_<task>`` for the metaworld suite)."""
    return f"local/omnid_{task}" if suite == "omnid" else f"local/omnid_{suite}_{task}"


def _camera_list(text: str) -> list[str]:
    """Comma-separated camera names (checked against the ``--suite``'s cameras after parsing)."""
    cameras = [c.strip() for c in text.split(",") if c.strip()]
    if not cameras:
        raise argparse.ArgumentTypeError(f"expected comma-separated cameras, e.g. cam_b,cam_c, got {text!r}")
    return cameras


def _hidden_camera_list(text: str) -> list[str]:
    """Comma-separated camera names, possibly none (checked against ``--cameras`` after parsing)."""
    return [c.strip() for c in text.split(",") if c.strip()]


def _check_suite_arguments(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Resolve the suite-dependent defaults of ``args`` (task, cameras) and check them against the suite
    (and ``--hidden-cameras`` against ``--cameras``)."""
    suite = args.suite
    if args.task is None:
        if suite != "omnid":
            parser.error(f"--task: --suite {suite} needs a task, one of {list(SUITE_TASKS[suite])}")
        args.task = "select_apple"
    if args.task not in SUITE_TASKS[suite]:
        parser.error(
            f"--task: expected one of {list(SUITE_TASKS[suite])} (--suite {suite}), got {args.task!r}"
        )
    if args.cameras is None:
        args.cameras = list(DEFAULT_CAMERAS[suite])
    try:
        validate_cameras("--cameras", args.cameras, SUITE_CAMERAS[suite])
    except ValueError as e:
        parser.error(f"{e} (comma-separated, e.g. {','.join(DEFAULT_CAMERAS[suite][:2])})")
    if args.hidden_cameras is not None:
        try:
            check_hidden_cameras("--hidden-cameras", args.hidden_cameras, args.cameras)
        except ValueError as e:
            parser.error(f"{e} (--cameras {','.join(args.cameras)})")
    if suite == "metaworld":
        for flag, value, default in (
            ("--layout", args.layout, "id"),
            ("--background", args.background, "id"),
            ("--rig", args.rig, DEFAULT_RIG),
        ):
            if value != default:
                parser.error(f"{flag}: the metaworld suite has no variants; expected {default}, got {value}")
        if args.task_onehot:
            parser.error(
                f"--task-onehot: the metaworld suite has no task one-hot (its tasks are not among "
                f"{list(TASKS)}); expected it off, got it on"
            )


def _image_size(text: str) -> int:
    try:
        return validate_image_size("image_size", int(text))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected an int number of pixels in [1, {MAX_IMAGE_SIDE}], got {text!r}"
        ) from None


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnid-record",
        description="Record scripted-expert episodes of an OmniD benchmark task (or a MetaWorld task) as a "
        "LeRobot dataset (videos of every camera with calibration, state, action, task text).",
    )
    parser.add_argument(
        "--suite",
        choices=SUITES,
        default="omnid",
        help="env suite: omnid (our benchmark) or metaworld (MetaWorld v3 tasks, needs the metaworld "
        "extra) (default: %(default)s)",
    )
    parser.add_argument(
        "--task",
        default=None,
        help=f"task: for --suite omnid one of {', '.join(TASKS)} (default: select_apple); for --suite "
        "metaworld a MetaWorld v3 name such as assembly-v3 (required)",
    )
    parser.add_argument(
        "--episodes",
        type=positive_int,
        default=50,
        help="successful episodes to save (default: %(default)s)",
    )
    parser.add_argument(
        "--layout",
        choices=LAYOUTS,
        default="id",
        help="object placement, omnid suite only (default: %(default)s)",
    )
    parser.add_argument(
        "--background",
        choices=BACKGROUNDS,
        default="id",
        help="table texture, omnid suite only (default: %(default)s)",
    )
    parser.add_argument(
        "--cameras",
        type=_camera_list,
        default=None,
        help=f"comma-separated cameras to record (default: {','.join(CAMERAS)}; for --suite metaworld "
        f"{','.join(metaworld_suite.DEFAULT_CAMERAS)})",
    )
    parser.add_argument(
        "--image-size", type=_image_size, default=128, help="square image side, pixels (default: %(default)s)"
    )
    parser.add_argument(
        "--rig",
        choices=RIGS,
        default=DEFAULT_RIG,
        help="placements of the fixed cameras, omnid suite only (default: %(default)s)",
    )
    calibration = parser.add_mutually_exclusive_group()
    calibration.add_argument(
        "--per-frame-calibration",
        dest="per_frame_calibration",
        action="store_true",
        default=True,
        help="write every camera's calibration in every frame (columns observation.extrinsics.<cam>, "
        "observation.intrinsics.<cam>): datasets of different rigs merge with lerobot-edit-dataset; "
        "needed for cam_wrist and MetaWorld's hand cameras (the default)",
    )
    calibration.add_argument(
        "--static-calibration",
        dest="per_frame_calibration",
        action="store_false",
        help="write each camera's calibration once, in its image feature's info (the form of older "
        "datasets; what --policy.calibration_path and omnid-robustness replace); such datasets of "
        "different rigs do not merge",
    )
    parser.add_argument(
        "--task-onehot",
        action="store_true",
        help="write the task as a one-hot over the six tasks in every frame (column "
        "observation.environment_state): datasets of different tasks then merge into one multi-task "
        "dataset whose policies are told the task (evaluate with --env.task_onehot=true); omnid suite only",
    )
    parser.add_argument(
        "--hidden-cameras",
        type=_hidden_camera_list,
        default=None,
        help="comma-separated cameras among --cameras that the episodes are meant not to show: every camera "
        "is still recorded with its real rendered images (not black ones), and the column "
        "observation.camera_visible (per recorded camera, 0.0 hidden, 1.0 visible) tells OmniD to leave the "
        "hidden ones out of its fusion. Its feature is the same whichever cameras are hidden, so e.g. "
        "new-camera episodes (--hidden-cameras cam_b,cam_c,cam_d,cam_e) and replayed training-camera "
        "episodes (--hidden-cameras cam_a), both with --cameras cam_a,...,cam_e, merge with "
        "lerobot-edit-dataset. '' writes the column with every camera visible (default: no column)",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="attempt i resets the env with seed + i (default: %(default)s)"
    )
    parser.add_argument(
        "--root",
        type=Path,
        default=None,
        help="output directory, must not exist or be empty (default: $HF_LEROBOT_HOME/<repo-id>)",
    )
    parser.add_argument(
        "--repo-id",
        default=None,
        help="dataset repo id (default: local/omnid_<task>, or local/omnid_metaworld_<task>)",
    )
    parser.add_argument(
        "--push-to-hub",
        action="store_true",
        help="upload the dataset with LeRobot's push_to_hub when complete",
    )
    parser.add_argument(
        "--max-attempts",
        type=positive_int,
        default=None,
        help="bound on expert episodes run, failed ones included (default: 2 * episodes + 10)",
    )
    return parser


def quiet_third_party_logs() -> None:
    """Keep the terminal to our progress bar and summary: no per-video encoder banners or per-episode bars."""
    import av
    import datasets

    os.environ.setdefault("SVT_LOG", "1")  # SVT-AV1 (LeRobot's default codec): errors only
    av.logging.set_libav_level(av.logging.ERROR)  # survives LeRobot restoring FFmpeg's default callback
    datasets.disable_progress_bars()


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.max_attempts is not None and args.max_attempts < args.episodes:
        parser.error(
            f"--max-attempts: expected at least --episodes ({args.episodes}), got {args.max_attempts}"
        )
    _check_suite_arguments(parser, args)
    try:
        check_wrist_calibration(args.cameras, args.per_frame_calibration, args.suite)
    except ValueError as e:
        parser.error(str(e))
    repo_id = args.repo_id or default_repo_id(args.suite, args.task)
    if args.push_to_hub and repo_id.startswith("local/"):
        parser.error(
            f"--repo-id: --push-to-hub needs your Hub namespace "
            f"(e.g. <user>/{default_repo_id(args.suite, args.task).removeprefix('local/')}), got {repo_id!r}"
        )
    root = args.root if args.root is not None else HF_LEROBOT_HOME / repo_id
    try:
        _check_root(root)
    except FileExistsError as e:
        parser.error(str(e))
    quiet_third_party_logs()
    summary = record_dataset(
        root,
        suite=args.suite,
        task=args.task,
        episodes=args.episodes,
        repo_id=repo_id,
        cameras=args.cameras,
        layout=args.layout,
        background=args.background,
        image_size=args.image_size,
        rig=args.rig,
        per_frame_calibration=args.per_frame_calibration,
        task_onehot=args.task_onehot,
        hidden_cameras=args.hidden_cameras,
        seed=args.seed,
        max_attempts=args.max_attempts,
        push_to_hub=args.push_to_hub,
    )
    print(summary.line())
    if summary.interrupted:
        return EXIT_INTERRUPTED
    if not summary.complete:
        print(
            f"error: only {summary.episodes} of {summary.requested} expert episodes succeeded within "
            f"--max-attempts={summary.attempts}; raise it to record more.",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
