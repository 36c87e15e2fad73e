"""``select_action`` latency of OmniD at the sizes the docs use: a new action chunk and a queued action.

What a synchronous deployment (``lerobot-rollout --inference.type=sync``) pays per control step: every
``n_action_steps`` (8) steps the policy generates a chunk (backbone on every camera, OFG, the diffusion
head's denoising loop); the other steps pop a queued action. All profiles measured side by side in one
run, with the ratio of each to the 100 ms control period of the sim robot (10 Hz).

    MUJOCO_GL=egl .venv/bin/python benchmarks/bench_select_action.py                  # mini, demo, examples
    MUJOCO_GL=egl .venv/bin/python benchmarks/bench_select_action.py --profiles paper --repeats 1

Profiles (4 cameras B-E with the sim's own calibration, 2 observation steps, horizon 16, 8 actions per
chunk, batch 1):

- ``mini``: the benchmark's ``mini`` profile (docs/benchmark.md) and ``examples/09_real_robot_path.sh``:
  64 px, 16x20x8 volume, d=64, 2 OFG layers, 16 plane keypoints, UNet 128-256-512, DDIM 10 steps;
- ``demo``: ``omnid-demo``'s CPU profile (README): the same model at 96 px;
- ``examples``: ``examples/_config.sh`` and the README quick start: 128 px, 32x40x16 volume, d=128, 6
  layers, flattened plane, UNet 512-1024-2048, DDIM 10 steps;
- ``paper``: the paper's configuration (docs/performance.md): 480 px, 64x16x64 volume, ResNet-18 at
  stride 32, DDPM 100 steps (slow on a CPU: use ``--repeats 1``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch
from gym_omnid import TRAIN_CAMERAS, WORKSPACE_BOUNDS
from lerobot.configs.types import FeatureType, PolicyFeature
from tqdm import tqdm

from lerobot_omnid.env_config import OmniDEnvConfig
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

CONTROL_PERIOD_MS = 100.0  # the sim robot's 10 Hz control step
STATE_DIM, ACTION_DIM = 16, 10  # the sim robot's state and action
CPU_MODEL = {
    "volume_bounds": WORKSPACE_BOUNDS,
    "volume_shape": (16, 20, 8),
    "backbone_layer": 3,
    "d_model": 64,
    "num_layers": 2,
    "checkpoint_sampling": False,
    "plane_readout": "keypoints",
    "compressed_channels": 16,
    "down_dims": (128, 256, 512),
    "noise_scheduler_type": "DDIM",
    "num_inference_steps": 10,
    "prediction_type": "sample",
}


@dataclass(frozen=True)
class Profile:
    image_size: int
    omnid: dict = field(default_factory=dict)  # OmniDConfig overrides


PROFILES = {
    "mini": Profile(64, CPU_MODEL),
    "demo": Profile(96, CPU_MODEL),
    "examples": Profile(
        128,
        {
            "volume_bounds": WORKSPACE_BOUNDS,
            "volume_shape": (32, 40, 16),
            "backbone_layer": 3,
            "noise_scheduler_type": "DDIM",
            "num_inference_steps": 10,
        },
    ),
    "paper": Profile(480),
}


def build_policy(profile: Profile) -> OmniDPolicy:
    """OmniD for the sim robot's 4 cameras at ``profile.image_size``, with their calibration."""
    size = profile.image_size
    calibration = OmniDEnvConfig(cameras=list(TRAIN_CAMERAS), image_size=size).camera_calibrations()
    config = OmniDConfig(
        input_features={
            "observation.state": PolicyFeature(FeatureType.STATE, (STATE_DIM,)),
            **{key: PolicyFeature(FeatureType.VISUAL, (3, size, size)) for key in calibration},
        },
        output_features={"action": PolicyFeature(FeatureType.ACTION, (ACTION_DIM,))},
        camera_calibration=calibration,
        device="cpu",
        push_to_hub=False,
        **profile.omnid,
    )
    return OmniDPolicy(config).eval()


def measure(name: str, policy: OmniDPolicy, threads: int, repeats: int) -> dict:
    """Median latency of a new chunk and of a queued action over ``repeats`` chunk cycles after a warm-up,
    with ``threads`` torch threads."""
    torch.manual_seed(0)
    torch.set_num_threads(threads)
    size = policy.config.input_features[policy.camera_keys[0]].shape[-1]
    obs = {key: torch.rand(1, 3, size, size) for key in policy.camera_keys}
    obs["observation.state"] = torch.randn(1, STATE_DIM)
    n_steps = policy.config.n_action_steps
    chunk_ms, queued_ms = [], []
    with torch.inference_mode():
        for cycle in tqdm(range(repeats + 1), desc=f"{name}, {threads} thread(s)", leave=False):
            policy.reset()  # empty queues: the first call generates a chunk
            for step in range(n_steps):
                start = time.perf_counter()
                policy.select_action(obs)
                elapsed = (time.perf_counter() - start) * 1e3
                if cycle > 0:  # the first cycle warms up allocators
                    (chunk_ms if step == 0 else queued_ms).append(elapsed)
    chunk, queued = statistics.median(chunk_ms), statistics.median(queued_ms)
    return {
        "profile": name,
        "threads": threads,
        "image_size": size,
        "params_M": sum(p.numel() for p in policy.parameters()) / 1e6,
        "chunk_ms": chunk,
        "queued_ms": queued,
        "mean_step_ms": (chunk + (n_steps - 1) * queued) / n_steps,
    }


def git_commit() -> str:
    """The repository's HEAD commit (short), or "unknown"."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).parent,
            capture_output=True,
            text=True,
            check=True,
        )
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return out.stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--profiles", default="mini,demo,examples", help=f"comma-separated, of {list(PROFILES)}"
    )
    parser.add_argument("--repeats", type=int, default=5, help="measured chunk cycles after one warm-up")
    parser.add_argument(
        "--threads",
        default=f"1,{torch.get_num_threads()}",
        help="comma-separated torch thread counts to measure each profile with (default: 1 and torch's)",
    )
    args = parser.parse_args()
    try:
        thread_counts = sorted({int(t) for t in args.threads.split(",")})
    except ValueError:
        thread_counts = []
    if not thread_counts or min(thread_counts) < 1:
        parser.error(f"--threads: expected comma-separated integers >= 1, got {args.threads!r}")
    names = args.profiles.split(",")
    unknown = [n for n in names if n not in PROFILES]
    if unknown:
        parser.error(f"--profiles: unknown {unknown}; expected names from {list(PROFILES)}")
    if args.repeats < 1:
        parser.error(f"--repeats: expected an integer >= 1, got {args.repeats}")
    load_before = os.getloadavg()[0]
    print(
        f"commit {git_commit()}, {os.cpu_count()} CPU cores, load average {load_before:.1f}; batch 1, "
        f"4 cameras, {args.repeats} chunk cycles per profile and thread count"
    )
    results = []
    for name in names:
        policy = build_policy(PROFILES[name])
        results += [measure(name, policy, threads, args.repeats) for threads in thread_counts]
    print(
        f"{'profile':<9} {'threads':>7} {'image':>7} {'params':>8} {'new chunk':>11} {'queued':>9} "
        f"{'mean/step':>10} {'chunk / 100 ms':>15}"
    )
    for r in results:
        print(
            f"{r['profile']:<9} {r['threads']:>7} {r['image_size']:>4} px {r['params_M']:>7.1f}M "
            f"{r['chunk_ms']:>8.1f} ms {r['queued_ms']:>6.2f} ms {r['mean_step_ms']:>7.1f} ms "
            f"{r['chunk_ms'] / CONTROL_PERIOD_MS:>14.2f}x"
        )
    base = results[0]
    if len(results) > 1:
        print(
            f"new chunk relative to {base['profile']} with {base['threads']} thread(s): "
            + ", ".join(
                f"{r['profile']}/{r['threads']} {r['chunk_ms'] / base['chunk_ms']:.2f}x" for r in results[1:]
            )
        )
    print(
        f"load average at the end {os.getloadavg()[0]:.1f} (a shared machine slows multi-threaded runs most)"
    )


if __name__ == "__main__":
    main()
