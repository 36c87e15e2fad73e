"""Shared test helpers: synthetic calibrated cameras, tiny OmniD configs, datasets and checkpoint folders,
plans of the experiment engine; importable from every test folder (pytest's ``pythonpath = ["tests"]``).

A plain module (not conftest.py): several folders have a conftest of their own, and ``from conftest import``
would resolve to whichever was imported first.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import torch
from gym_omnid import TRAIN_CAMERAS, WORKSPACE_BOUNDS
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig

from lerobot_omnid.geometry import look_at
from lerobot_omnid.keys import image_key
from lerobot_omnid.measure.engine import Run
from lerobot_omnid.policy.configuration_omnid import OmniDConfig

COMMITTED_SUMMARIES = Path(__file__).resolve().parents[1] / "docs" / "results"
"""The run summaries committed beside docs/results.md, from which each claim's table is rebuilt."""

# Camera eyes around a table whose workspace is centred at (0.5, 0, 0) in the robot base frame.
SYNTHETIC_EYES = {
    "cam_a": (0.1, 0.0, 1.1),
    "cam_b": (1.3, 0.0, 0.6),
    "cam_c": (0.5, 0.8, 0.6),
    "cam_d": (0.5, -0.8, 0.6),
    "cam_e": (-0.2, 0.0, 0.8),
}
WORKSPACE_CENTRE = (0.5, 0.0, 0.0)
STATE_DIM = 10
ACTION_DIM = 10
TINY_POLICY_FLAGS = [  # `lerobot-train` options of a CPU-tiny OmniD
    "--policy.type=omnid",
    "--policy.device=cpu",
    "--policy.push_to_hub=false",
    "--policy.volume_bounds=[[0.2,0.8],[-0.3,0.3],[0.0,0.3]]",
    "--policy.volume_shape=[8,8,4]",
    "--policy.d_model=32",
    "--policy.num_heads=2",
    "--policy.num_layers=1",
    "--policy.down_dims=[32,64]",
    "--policy.backbone_layer=3",
    "--policy.noise_scheduler_type=DDIM",
    "--policy.num_inference_steps=2",
]


def synthetic_calibration(cam: str, size: int = 64, target=WORKSPACE_CENTRE) -> dict:
    """Calibration dict of a pinhole camera (90 degree field of view) looking at the workspace."""
    eye = torch.tensor(SYNTHETIC_EYES[cam], dtype=torch.float64)
    cam_T_world = look_at(eye, torch.tensor(target, dtype=torch.float64))
    f = size / 2
    K = [[f, 0.0, (size - 1) / 2], [0.0, f, (size - 1) / 2], [0.0, 0.0, 1.0]]
    return {"K": K, "T_cam_world": cam_T_world.tolist(), "image_size": [size, size]}


def tiny_config(cams=("cam_b", "cam_c", "cam_d", "cam_e"), size: int = 64, **overrides) -> OmniDConfig:
    """A small OmniD config (CPU-friendly) with synthetic calibrated cameras."""
    keys = [f"observation.images.{c}" for c in cams]
    kwargs = {
        "input_features": {
            "observation.state": PolicyFeature(FeatureType.STATE, (STATE_DIM,)),
            **{k: PolicyFeature(FeatureType.VISUAL, (3, size, size)) for k in keys},
        },
        "output_features": {"action": PolicyFeature(FeatureType.ACTION, (ACTION_DIM,))},
        "camera_calibration": {k: synthetic_calibration(c, size) for k, c in zip(keys, cams, strict=True)},
        "volume_bounds": ((0.2, 0.8), (-0.3, 0.3), (0.0, 0.3)),
        "volume_shape": (8, 8, 4),
        "d_model": 32,
        "num_heads": 2,
        "num_layers": 2,
        "ffn_dim": 64,
        "dropout": 0.0,
        "down_dims": (32, 64),
        "backbone_layer": 3,
        "noise_scheduler_type": "DDIM",
        "num_inference_steps": 3,
        "device": "cpu",
        "push_to_hub": False,
    }
    kwargs.update(overrides)
    return OmniDConfig(**kwargs)


def tiny_diffusion_config(cams=("cam_b", "cam_c"), size: int = 32) -> DiffusionConfig:
    """A small LeRobot Diffusion Policy config: 5-D state, 4-D action, one ResNet-18 shared by ``cams``."""
    image = PolicyFeature(FeatureType.VISUAL, (3, size, size))
    return DiffusionConfig(
        input_features={
            "observation.state": PolicyFeature(FeatureType.STATE, (5,)),
            **{f"observation.images.{c}": image for c in cams},
        },
        output_features={"action": PolicyFeature(FeatureType.ACTION, (4,))},
        down_dims=(16, 32),
        horizon=8,
        n_action_steps=4,
        crop_shape=None,
        pretrained_backbone_weights=None,
        use_group_norm=True,
        use_separate_rgb_encoder_per_camera=False,
        device="cpu",
    )


def random_batch(config: OmniDConfig, batch_size: int = 2, generator: torch.Generator | None = None) -> dict:
    """A training batch matching ``config`` (images in [0, 1], normalised state and action)."""
    T = config.n_obs_steps
    batch = {
        key: torch.rand(batch_size, T, *ft.shape, generator=generator)
        for key, ft in config.image_features.items()
    }
    batch["observation.state"] = torch.randn(batch_size, T, STATE_DIM, generator=generator)
    batch["action"] = torch.randn(batch_size, config.horizon, ACTION_DIM, generator=generator)
    batch["action_is_pad"] = torch.zeros(batch_size, config.horizon, dtype=torch.bool)
    return batch


def make_tiny_dataset(
    root,
    cams=("cam_a", "cam_b", "cam_c", "cam_d", "cam_e"),
    size: int = 64,
    episodes: int = 2,
    frames: int = 20,
):
    """A small LeRobotDataset written by ``LeRobotDataset.create``: random video cameras with calibration
    in their feature info, random state and action."""
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    features = {
        "observation.state": {
            "dtype": "float32",
            "shape": (STATE_DIM,),
            "names": [f"s{i}" for i in range(STATE_DIM)],
        },
        "action": {"dtype": "float32", "shape": (ACTION_DIM,), "names": [f"a{i}" for i in range(ACTION_DIM)]},
    }
    for cam in cams:
        features[f"observation.images.{cam}"] = {
            "dtype": "video",
            "shape": (size, size, 3),
            "names": ["height", "width", "channels"],
            "info": {"calibration": synthetic_calibration(cam, size)},
        }
    dataset = LeRobotDataset.create("local/tiny", fps=10, features=features, root=root, use_videos=True)
    rng = np.random.default_rng(0)
    for _ in range(episodes):
        for _ in range(frames):
            frame = {
                f"observation.images.{c}": rng.integers(0, 256, (size, size, 3), dtype=np.uint8) for c in cams
            }
            frame["observation.state"] = rng.standard_normal(STATE_DIM).astype(np.float32)
            frame["action"] = rng.standard_normal(ACTION_DIM).astype(np.float32)
            frame["task"] = "put the apple in the bowl"
            dataset.add_frame(frame)
        dataset.save_episode()
    dataset.finalize()
    return dataset


def record_rig(root, rig: str, per_frame_calibration: bool, cameras, size: int = 32):
    """One select_apple expert episode recorded by ``omnid-record``'s own function with ``rig``'s cameras."""
    from lerobot_omnid.record import record_dataset

    summary = record_dataset(
        root,
        episodes=1,
        cameras=list(cameras),
        image_size=size,
        rig=rig,
        per_frame_calibration=per_frame_calibration,
        repo_id=f"local/{root.name}",
        show_progress=False,
    )
    assert summary.complete
    return root


def record_five_cameras(root: Path, size: int) -> Path:
    """Two select_apple expert episodes with all five cameras, recorded by ``omnid-record``'s own function
    with its defaults (repo id, per-frame calibration)."""
    from gym_omnid.constants import CAMERAS

    from lerobot_omnid.record import record_dataset

    summary = record_dataset(root, episodes=2, cameras=CAMERAS, image_size=size, seed=0, show_progress=False)
    assert summary.complete and not summary.interrupted
    return root


def record_rigs_with_default_flags(parent: Path, rigs, camera: str, size: int) -> dict[str, Path]:
    """One expert episode per rig, recorded by ``omnid-record`` (its ``main``) with no calibration flag, into
    ``parent/<rig>`` with repo id ``local/<rig>``."""
    from lerobot_omnid.record import main

    roots = {}
    for rig in rigs:
        roots[rig] = parent / rig
        argv = ["--episodes", "1", "--cameras", camera, "--image-size", str(size), "--rig", rig]
        assert main([*argv, "--root", str(roots[rig]), "--repo-id", f"local/{rig}"]) == 0
    return roots


def load_recording(root: Path, repo_id: str = "local/omnid_select_apple"):
    """The LeRobotDataset ``omnid-record`` wrote under ``root`` (default: its repo id for select_apple),
    decoded with PyAV."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(repo_id, root=root, video_backend="pyav")


def assert_only_dataset_dirs(root: Path) -> None:
    """Nothing half-written: no staging images or temporary encoder folders left behind."""
    assert sorted(p.name for p in root.iterdir()) == ["data", "meta", "videos"]


CHECKPOINT_IMAGE_SIZE = 64  # px: the images of the checkpoints written by checkpoint_dir


def checkpoint_config(policy_type: str, calibrations: dict) -> dict:
    """The config.json content of a checkpoint of ``policy_type`` with cameras B-E at 64 px."""
    size = CHECKPOINT_IMAGE_SIZE
    features = {"observation.state": {"type": "STATE", "shape": [16]}}
    features |= {image_key(c): {"type": "VISUAL", "shape": [3, size, size]} for c in TRAIN_CAMERAS}
    config = {"type": policy_type, "input_features": features}
    if policy_type == "omnid":
        config |= {"camera_calibration": dict(calibrations), "volume_bounds": WORKSPACE_BOUNDS}
    return config


def checkpoint_dir(root: Path, policy_type: str, calibrations: dict) -> Path:
    """A folder with the config.json and train_config.json of a checkpoint of ``policy_type``."""
    root.mkdir(parents=True)
    (root / "config.json").write_text(json.dumps(checkpoint_config(policy_type, calibrations)))
    (root / "train_config.json").write_text(json.dumps({"seed": 1000}))
    return root


def flag(cmd, name: str) -> str | None:
    """Value of ``--name=value`` in a command (None if absent)."""
    values = [a.split("=", 1)[1] for a in cmd if a.startswith(f"--{name}=")]
    assert len(values) <= 1, (name, values)
    return values[0] if values else None


def by_name(runs):
    """A plan's runs by name."""
    return {r.name: r for r in runs}


WRITE_EVAL = (
    "import json, pathlib, sys; p = pathlib.Path(sys.argv[1]); p.mkdir(parents=True, exist_ok=True); "
    "(p / 'eval_info.json').write_text(json.dumps({'overall': {'pc_success': float(sys.argv[2]), "
    "'n_episodes': 1}}))"
)


def evaluation(out: Path, name: str, rate: str = "0", needs=(), inputs=()) -> Run:
    """An engine run whose tool is a tiny Python command writing an eval_info.json of success ``rate``."""
    folder = out / name
    cmd = (sys.executable, "-c", WRITE_EVAL, str(folder), rate)
    return Run(name, "eval", cmd, folder, tuple(needs), inputs=tuple(inputs))


def static_and_per_frame_twins(tmp_path: Path, cams: tuple[str, ...], episodes: int, frames: int):
    """A tiny dataset under ``tmp_path / "static"`` (static calibration), its copy under
    ``tmp_path / "columns"`` whose per-frame columns hold that calibration, and two OmniD policies with the
    same weights, calibrated statically and per frame: the same predictions are expected from each on its
    dataset. The plane enters the condition from the start, so that images and calibration move them.
    Returns (dataset, the copy's root, static policy, per-frame policy)."""
    from lerobot_omnid.calibration.attach_calibration import main as attach_calibration
    from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

    keys = [f"observation.images.{cam}" for cam in cams]
    static_root, columns_root = tmp_path / "static", tmp_path / "columns"
    dataset = make_tiny_dataset(static_root, cams=cams, size=32, episodes=episodes, frames=frames)
    assert attach_calibration(["--root", str(static_root), "--per-frame-columns", str(columns_root)]) == 0
    static = OmniDPolicy(tiny_config(cams, size=32, zero_init_compression=False))
    per_frame = OmniDPolicy(
        tiny_config(cams, size=32, zero_init_compression=False, camera_calibration={}, frame_calibration=keys)
    )
    per_frame.load_state_dict(static.state_dict())
    return dataset, columns_root, static, per_frame


def command_options(cmd) -> dict[str, str]:
    """A command line's ``--name=value`` options as a mapping (``--name value`` pairs are left out)."""
    return dict(arg.partition("=")[::2] for arg in cmd[1:] if arg.startswith("--"))
