"""``omnid-viz``: see what OmniD sees, from a checkpoint and a dataset episode or a live env.

For each camera: the image with the volume's anchors projected (coloured by height) and, for one query,
its sampling locations sized and coloured by attention weight; the channel-pooled plane feature as a
heatmap in the robot base frame (with the objects' true positions in env mode); the share of attention
each camera receives. A grid PNG for one step, or an mp4 over an episode with ``--video``.

Examples::

    omnid-viz --policy-path outputs/omnid/checkpoints/last/pretrained_model \\
        --dataset-root data/select_apple --episode 0 --frame 30 --out viz/
    MUJOCO_GL=egl omnid-viz --policy-path ... --env-task select_apple --seed 1 --video --out viz/

The OFG fuses every observation step on its own, so the current frame's fusion shown here is exactly
what the policy computes for that step. Runs on CPU (``--device cuda`` when available).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from lerobot_omnid.calibration.frame_columns import (
    extrinsics_from_column,
    extrinsics_key,
    intrinsics_from_column,
    intrinsics_key,
)
from lerobot_omnid.calibration.schema import (
    CALIBRATION_INFO_KEY,
    CalibrationError,
    CameraCalibration,
    camera_matrices,
)
from lerobot_omnid.cli import int_at_least
from lerobot_omnid.keys import IMAGE_KEY_PREFIX, camera_name, image_key
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.viz.drawing import FrameData, draw_frame, figure_rgb, frame_data, write_mp4

DEFAULT_MAX_ANCHORS = 2500  # anchors drawn per camera at most (a regular sub-lattice of the volume)
CALIBRATION_ATOL = 1e-3  # m and px: checkpoint and source calibrations closer than this agree


class VizError(ValueError):
    """Bad input to omnid-viz; the message names the option, the expected and the actual value."""


@dataclass
class Observation:
    """One step to draw: images per camera name (H, W, 3) uint8, a label, its frame index or env step,
    and the objects' world positions (m) when the source knows them."""

    images: dict[str, np.ndarray]
    label: str
    index: int
    objects: dict[str, np.ndarray] = field(default_factory=dict)


class DatasetSource:
    """Frames of one episode of a LeRobot dataset (v3, decoded with PyAV)."""

    def __init__(self, root: Path, repo_id: str | None, episode: int) -> None:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

        if not (root / "meta" / "info.json").is_file():
            raise VizError(f"--dataset-root: expected a LeRobot dataset (with meta/info.json), got {root}")
        self.repo_id = repo_id or f"local/{root.name}"
        self.meta = LeRobotDatasetMetadata(self.repo_id, root=root)
        if not 0 <= episode < self.meta.total_episodes:
            raise VizError(
                f"--episode: expected an episode index in [0, {self.meta.total_episodes - 1}] "
                f"for the dataset at {root}, got {episode}"
            )
        self.episode, self.fps, self.stem = episode, self.meta.fps, f"{root.name}_ep{episode:03d}"
        self.cameras = [
            camera_name(k)
            for k, ft in self.meta.features.items()
            if k.startswith(IMAGE_KEY_PREFIX) and ft["dtype"] in ("video", "image")
        ]
        self.dataset = LeRobotDataset(self.repo_id, root=root, episodes=[episode], video_backend="pyav")
        self.num_frames = len(self.dataset)

    def calibration(self, cam: str) -> CameraCalibration | None:
        """The camera's calibration: its feature info's, else its per-frame columns' (``omnid-record``'s
        default), which must then be constant over the episode (omnid-viz draws fixed cameras)."""
        key = image_key(cam)
        calib = (self.meta.features[key].get("info") or {}).get(CALIBRATION_INFO_KEY)
        if calib is not None:
            return CameraCalibration.from_dict(calib, camera=key)
        columns = (intrinsics_key(cam), extrinsics_key(cam))
        if not all(column in self.meta.features for column in columns):
            return None
        frames = self.dataset.hf_dataset.select_columns(["episode_index", *columns]).with_format("numpy")
        episode = np.asarray(frames["episode_index"]) == self.episode
        K, cam_T_world = (np.stack(frames[column])[episode] for column in columns)
        for column, values in zip(columns, (K, cam_T_world), strict=True):
            if not np.array_equal(values, np.broadcast_to(values[0], values.shape)):
                raise VizError(
                    f"--dataset-root: {column}: expected a fixed camera (constant columns over episode "
                    f"{self.episode}), got values that change between frames; omnid-viz draws fixed cameras"
                )
        return CameraCalibration.from_dict(
            {
                "K": intrinsics_from_column(K[0]).tolist(),
                "T_cam_world": extrinsics_from_column(cam_T_world[0]).tolist(),
                "image_size": list(self.image_hw(cam)),
            },
            camera=key,
        )

    def image_hw(self, cam: str) -> tuple[int, int]:
        return tuple(self.meta.features[image_key(cam)]["shape"][:2])

    def observations(self, frames: Sequence[int], cameras: Sequence[str]) -> Iterator[Observation]:
        for frame in frames:
            item = self.dataset[frame]
            images = {c: (item[image_key(c)].permute(1, 2, 0) * 255).round().byte().numpy() for c in cameras}
            yield Observation(images, f"{self.repo_id} episode {self.episode} frame {frame}", frame)

    def close(self) -> None:
        pass


class EnvSource:
    """A gym_omnid env driven by its scripted expert; knows the objects' true positions."""

    def __init__(self, task: str, seed: int, **env_kwargs) -> None:
        import gym_omnid
        import gymnasium as gym

        self.task, self.seed, self.fps, self.stem = task, seed, gym_omnid.CONTROL_FPS, f"{task}_seed{seed}"
        self.env = gym.make(f"gym_omnid/{task}", disable_env_checker=True, **env_kwargs)

    def calibration(self, cam: str) -> CameraCalibration:
        from lerobot_omnid.env_config import calibration_dict

        return CameraCalibration.from_dict(calibration_dict(self.env.unwrapped, cam, image_key(cam)))

    def observations(self, steps: int | None) -> Iterator[Observation]:
        """The reset observation, then one per expert step until ``steps`` steps or the episode's end."""
        from gym_omnid.experts import make_expert

        obs, info = self.env.reset(seed=self.seed)
        expert = make_expert(self.env.unwrapped)
        step, done = 0, False
        while True:
            label = f"{self.task} seed {self.seed} step {step}" + (" (success)" if info["is_success"] else "")
            yield Observation(dict(obs["pixels"]), label, step, self.env.unwrapped.object_positions())
            if done or (steps is not None and step >= steps):
                return
            obs, _, terminated, truncated, info = self.env.step(expert.act())
            step, done = step + 1, terminated or truncated

    def close(self) -> None:
        self.env.close()


def load_config(policy_path: Path, device: str) -> tuple[Path, OmniDConfig]:
    """The checkpoint folder (``policy_path`` or its ``pretrained_model``) and its validated config."""
    from lerobot.configs import PreTrainedConfig

    path = next(
        (p for p in (policy_path, policy_path / "pretrained_model") if (p / "model.safetensors").is_file()),
        None,
    )
    if path is None or not (path / "config.json").is_file():
        raise VizError(
            f"--policy-path: expected a checkpoint folder with config.json and model.safetensors "
            f"(e.g. outputs/<run>/checkpoints/last/pretrained_model), got {policy_path}"
        )
    config = PreTrainedConfig.from_pretrained(path)
    if not isinstance(config, OmniDConfig):
        raise VizError(f"--policy-path: expected an omnid checkpoint, got policy type {config.type!r}")
    if not config.use_ofg:
        raise VizError(
            "--policy-path: expected a checkpoint with the OFG, got use_ofg=false (the 'w/o OFG' ablation "
            "has no BEV feature or attention to show)"
        )
    config.device = device
    return path, config


def resolve_calibrations(config: OmniDConfig, cameras: Sequence[str], source) -> list[CameraCalibration]:
    """Each camera's calibration: the checkpoint's (what the policy uses), else the source's."""
    calibs = []
    for cam in cameras:
        key, theirs = image_key(cam), source.calibration(cam)
        if key in config.camera_calibration:
            calibs.append(config.calibration(key))
            if theirs is not None and _differ(calibs[-1], theirs):
                tqdm.write(
                    f"warning: {cam}: the checkpoint's calibration differs from the source's; drawing and "
                    f"fusing with the checkpoint's (what the policy would use)"
                )
        elif theirs is not None:
            calibs.append(theirs)
        else:
            known = sorted(config.camera_calibration) or "none"
            raise VizError(
                f"--policy-path: expected a calibration of {key} in the checkpoint or the dataset, got none "
                f"(calibrated in the checkpoint: {known})"
            )
    return calibs


def _differ(a: CameraCalibration, b: CameraCalibration) -> bool:
    return not (
        np.allclose(a.T_cam_world, b.T_cam_world, atol=CALIBRATION_ATOL)
        and np.allclose(a.K, b.resized(a.image_size).K, atol=CALIBRATION_ATOL)
    )


def _select_cameras(requested, policy_cams: list[str], available: Sequence[str], where: str) -> list[str]:
    if requested is None:
        cams = [c for c in policy_cams if c in available]
        if not cams:
            raise VizError(
                f"--cameras: none of the checkpoint's cameras {policy_cams} is in {where} "
                f"({list(available)}); name the cameras to fuse with --cameras"
            )
        return cams
    cams = [camera_name(c) for c in requested]
    if not cams or len(set(cams)) != len(cams) or not set(cams) <= set(available):
        raise VizError(
            f"--cameras: expected distinct names from {list(available)} ({where}), got {requested}"
        )
    return cams


@dataclass
class VizSummary:
    """What one omnid-viz run wrote: files, frames drawn, cameras and their mean attention share."""

    files: list[Path]
    frames: int
    cameras: list[str]
    share: np.ndarray
    wall_time_s: float
    last: FrameData | None = None  # what the last frame drew (for inspection and tests)

    def lines(self) -> str:
        shares = ", ".join(f"{c} {100 * s:.1f}%" for c, s in zip(self.cameras, self.share, strict=True))
        head = f"omnid-viz: {len(self.files)} file(s), {self.frames} frame(s) in {self.wall_time_s:.1f} s:"
        return "\n".join([head, *(f"  {f}" for f in self.files), f"attention share per camera: {shares}"])


def visualize(
    policy_path: str | Path,
    out: str | Path,
    *,
    dataset_root: str | Path | None = None,
    repo_id: str | None = None,
    episode: int = 0,
    frame: int = 0,
    env_task: str | None = None,
    env_kwargs: dict | None = None,
    seed: int = 0,
    steps: int | None = None,
    video: bool = False,
    query: tuple[int, int] | None = None,
    cameras: Sequence[str] | None = None,
    stride: int = 1,
    device: str = "cpu",
    dpi: int = 100,
    max_anchors: int = DEFAULT_MAX_ANCHORS,
    show_progress: bool = True,
) -> VizSummary:
    """Draw what a checkpoint's OFG sees (see ``omnid-viz --help`` for the options).

    The source is ``dataset_root`` (with ``episode`` and ``frame``) or ``env_task`` (with ``seed``,
    ``steps`` and gym ``env_kwargs`` such as ``layout`` and ``background``). ``steps``: expert steps
    before the PNG (default 0) or the video's length (default: until the episode ends).
    """
    from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

    start = time.perf_counter()
    if (dataset_root is None) == (env_task is None):
        raise VizError("expected exactly one source: --dataset-root or --env-task")
    path, config = load_config(Path(policy_path), device)
    volume = config.feature_volume
    if query is not None and not all(0 <= i < n for i, n in zip(query, volume.plane_shape, strict=True)):
        raise VizError(
            f"--query: expected i,j with 0 <= i < {volume.plane_shape[0]} and 0 <= j < "
            f"{volume.plane_shape[1]} (the checkpoint's query plane), got {query}"
        )
    policy_cams = [camera_name(k) for k in config.image_features]
    if dataset_root is not None:
        source = DatasetSource(Path(dataset_root), repo_id, episode)
        cams = _select_cameras(cameras, policy_cams, source.cameras, f"the dataset at {dataset_root}")
        sizes = {source.image_hw(c) for c in cams}
        if len(sizes) > 1:
            raise VizError(f"--cameras: expected cameras of one image size, got sizes {sorted(sizes)}")
        image_hw = sizes.pop()
        if not video and not 0 <= frame < source.num_frames:
            raise VizError(
                f"--frame: expected a frame in [0, {source.num_frames - 1}] (episode {episode} has "
                f"{source.num_frames}), got {frame}"
            )
        indices = range(0, source.num_frames, stride) if video else [frame]
        observations, total = source.observations(indices, cams), len(indices)
    else:
        from gym_omnid.constants import CAMERAS

        cams = _select_cameras(cameras, policy_cams, CAMERAS, f"the {env_task} env")
        template = config.image_features.get(image_key(cams[0])) or next(iter(config.image_features.values()))
        image_hw = tuple(template.shape[1:])
        source = EnvSource(env_task, seed, cameras=tuple(cams), image_size=image_hw, **(env_kwargs or {}))
        run = source.observations(steps if video or steps is not None else 0)
        observations = (o for i, o in enumerate(run) if i % stride == 0) if video else run
        total = None if steps is None else steps // stride + 1
    try:
        calibs = resolve_calibrations(config, cams, source)
        config.cameras = cams
        # One calibration per camera for the whole run, static: a checkpoint that reads its cameras'
        # calibration from every frame's columns gets the source's here instead.
        config.frame_calibration = []
        config.camera_calibration.update(
            {image_key(c): k.to_dict() for c, k in zip(cams, calibs, strict=True)}
        )
        with contextlib.redirect_stdout(io.StringIO()):  # LeRobot prints "Loading weights from ..."
            policy = OmniDPolicy.from_pretrained(path, config=config)
        # The displayed images' matrices (to draw the objects) and the backbone input's (to fuse): one
        # function builds both, equal unless the checkpoint resizes its images.
        pix_T_cam, cam_T_world = camera_matrices(calibs, [image_hw] * len(calibs))
        input_pix_T_cam, input_cam_T_world = policy.camera_matrices(1, image_hw)
        shares, last = [], []  # attention shares of every frame drawn; the last FrameData
        name = "/".join([p for p in path.parts if p not in ("checkpoints", "pretrained_model")][-2:])

        def render(obs: Observation) -> FrameData:
            images = {c: obs.images[c] for c in cams}
            x = torch.stack([torch.from_numpy(im).permute(2, 0, 1) for im in images.values()]).float() / 255
            with torch.no_grad():  # S, 3, H, W -> B=1, T=1, S, 3, H, W
                _, ofg = policy.model.encode_images(
                    x[None, None].to(input_pix_T_cam.device), input_pix_T_cam, input_cam_T_world
                )
            title = f"{obs.label}   [checkpoint {name}]"
            data = frame_data(
                ofg, volume, images, pix_T_cam, cam_T_world, obs.objects, query, max_anchors, title
            )
            shares.append(data.share_all)
            last[:] = [data]
            return data

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        if video:
            bar = tqdm(observations, total=total, unit="frame", desc="omnid-viz", disable=not show_progress)
            target = out / f"{source.stem}.mp4"
            write_mp4(
                target, (figure_rgb(draw_frame(render(o), volume, dpi)) for o in bar), source.fps / stride
            )
        else:
            *_, obs = observations  # the last one: the requested frame, or the state after `steps`
            target = out / f"{source.stem}_{'frame' if dataset_root else 'step'}{obs.index:04d}.png"
            draw_frame(render(obs), volume, dpi).savefig(target, dpi=dpi)
    finally:
        source.close()
    share = np.mean(shares, axis=0)
    return VizSummary([target], len(shares), cams, share, time.perf_counter() - start, last[0])


def _query(text: str) -> tuple[int, int]:
    try:
        i, j = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected plane indices i,j (e.g. 12,8), got {text!r}") from None
    return i, j


def build_parser() -> argparse.ArgumentParser:
    from gym_omnid.constants import BACKGROUNDS, LAYOUTS, TASKS

    parser = argparse.ArgumentParser(
        prog="omnid-viz",
        description="See what OmniD sees: per camera the projected volume anchors and one query's deformable "
        "attention samples, the BEV feature in the robot base frame and each camera's attention share. "
        "A grid PNG of one step, or an mp4 over an episode with --video.",
    )
    add = parser.add_argument
    add(
        "--policy-path",
        type=Path,
        required=True,
        help="checkpoint (.../checkpoints/<step>[/pretrained_model])",
    )
    add("--out", type=Path, required=True, help="output directory (created if needed)")
    add("--dataset-root", type=Path, help="source: a LeRobot dataset directory")
    add("--repo-id", help="its repo id (default: local/<directory name>)")
    add("--episode", type=int_at_least(0), help="dataset episode (default: 0)")
    add("--frame", type=int_at_least(0), help="frame of the episode for the PNG (default: 0)")
    add("--env-task", choices=TASKS, help="source: a gym_omnid env driven by the scripted expert")
    add("--layout", choices=LAYOUTS, default="id", help="env object placement (default: %(default)s)")
    add("--background", choices=BACKGROUNDS, default="id", help="env table texture (default: %(default)s)")
    add("--seed", type=int, default=0, help="env reset seed (default: %(default)s)")
    add(
        "--steps",
        type=int_at_least(0),
        help="env: expert steps before the PNG (default: 0) or video length "
        "(default: until the episode ends)",
    )
    add("--video", action="store_true", help="write an mp4 over the episode instead of a PNG")
    add("--stride", type=int_at_least(1), default=1, help="video: draw every k-th frame (default: 1)")
    add(
        "--query",
        type=_query,
        help="plane cell i,j whose samples are drawn (default: the cell under the "
        "env's first object, else the plane centre)",
    )
    add(
        "--cameras",
        type=lambda t: [c.strip() for c in t.split(",") if c.strip()],
        help="comma-separated cameras to fuse (default: the checkpoint's); a camera the checkpoint has no "
        "calibration for takes the source's",
    )
    add("--device", default="cpu", help="torch device (default: %(default)s)")
    add("--dpi", type=int_at_least(30), default=100, help="figure resolution (default: %(default)s)")
    add(
        "--max-anchors",
        type=int_at_least(1),
        default=DEFAULT_MAX_ANCHORS,
        help="anchors drawn per camera at most (default: %(default)s)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if (args.dataset_root is None) == (args.env_task is None):
        parser.error("expected exactly one source: --dataset-root DIR or --env-task TASK")
    dataset_only = [k for k in ("repo_id", "episode", "frame") if getattr(args, k) is not None]
    if args.env_task is not None and dataset_only:
        parser.error(
            f"{', '.join('--' + k.replace('_', '-') for k in dataset_only)}: only with --dataset-root"
        )
    if args.dataset_root is not None and args.steps is not None:
        parser.error("--steps: only with --env-task (use --frame with a dataset)")
    if args.video and args.frame is not None:
        parser.error("--frame: a single frame is a PNG; --video draws the whole episode")
    from lerobot_omnid.record import quiet_third_party_logs

    quiet_third_party_logs()
    try:
        summary = visualize(
            args.policy_path, args.out, dataset_root=args.dataset_root, repo_id=args.repo_id,
            episode=args.episode or 0, frame=args.frame or 0, env_task=args.env_task,
            env_kwargs={"layout": args.layout, "background": args.background}, seed=args.seed,
            steps=args.steps, video=args.video, query=args.query, cameras=args.cameras, stride=args.stride,
            device=args.device, dpi=args.dpi, max_anchors=args.max_anchors,
        )  # fmt: skip
    except (VizError, CalibrationError) as e:
        parser.error(str(e))
    print(summary.lines())
    return 0


if __name__ == "__main__":
    sys.exit(main())
