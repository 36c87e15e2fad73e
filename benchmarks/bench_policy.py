"""OmniD vs LeRobot's stock Diffusion Policy on one synthetic batch: step time, latency, peak memory.

Both policies see the same cameras, image size, batch, horizon and inference steps; each is measured in
its own fresh process (so peak memory is its own) and the ratios are printed side by side.

    python benchmarks/bench_policy.py --profile cpu      # small configuration, minutes on 2 CPU cores
    python benchmarks/bench_policy.py --profile paper    # the paper's (64x16x64 grid, 4 cameras, 480x480,
                                                         # batch 8); use --device cuda on a GPU machine

``--json FILE`` keeps a run's numbers and ``--report-only FILE`` prints its table again.
``--against FIELD=JSON`` times instead OmniD with and without an option, in one process with their
training steps alternating (A B, B A, ...), so a busy machine slows both alike and the printed ratio stays
meaningful where absolute times do not (e.g. on 2 shared CPU cores):

    python benchmarks/bench_policy.py --against fuse_last_step_only=true

Peak memory: ``torch.cuda.max_memory_allocated`` on CUDA; on CPU the process's peak resident set size
(``ru_maxrss``) minus the resident size before the policy was built.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import resource
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from lerobot_omnid.measure.results import RunSummary, read_run_summary, write_run_summary

CAMERAS = ("cam_b", "cam_c", "cam_d", "cam_e")
PROTOCOL = "bench_policy"
STATE_DIM = ACTION_DIM = 10


@dataclass(frozen=True)
class Profile:
    image_size: int
    batch_size: int
    omnid: dict  # OmniDConfig overrides
    diffusion: dict  # DiffusionConfig overrides
    inference_steps: int = 10


PROFILES = {
    # What the CPU benchmark and tests use: 96x96 images, small volume and UNet for both policies.
    "cpu": Profile(
        image_size=96,
        batch_size=8,
        omnid={
            "volume_bounds": ((0.2, 0.8), (-0.3, 0.3), (0.0, 0.3)),
            "volume_shape": (16, 16, 8),
            "d_model": 64,
            "num_layers": 2,
            "backbone_layer": 3,
            "down_dims": (128, 256, 512),
            "checkpoint_sampling": False,  # memory is no concern at this size; skip the recomputation
        },
        diffusion={"down_dims": (128, 256, 512)},
    ),
    # The paper's setting (section 3): ResNet-18, 64x16x64 volume, d=128, 6 layers, 480x480 images.
    "paper": Profile(image_size=480, batch_size=8, omnid={}, diffusion={}),
}


def synthetic_calibration(cam_index: int, size: int) -> dict:
    from lerobot_omnid.geometry import look_at

    eyes = [(1.6, 0.0, 0.8), (0.6, 0.9, 0.8), (0.6, -0.9, 0.8), (-0.3, 0.0, 1.0)]
    cam_T_world = look_at(torch.tensor(eyes[cam_index]), torch.tensor([0.6, 0.0, 0.1]))
    f = size / 2
    K = [[f, 0.0, (size - 1) / 2], [0.0, f, (size - 1) / 2], [0.0, 0.0, 1.0]]
    return {"K": K, "T_cam_world": cam_T_world.tolist(), "image_size": [size, size]}


def build_policy(name: str, profile: Profile, device: str):
    from lerobot.configs.types import FeatureType, PolicyFeature

    size = profile.image_size
    keys = [f"observation.images.{c}" for c in CAMERAS]
    common = {
        "input_features": {
            "observation.state": PolicyFeature(FeatureType.STATE, (STATE_DIM,)),
            **{k: PolicyFeature(FeatureType.VISUAL, (3, size, size)) for k in keys},
        },
        "output_features": {"action": PolicyFeature(FeatureType.ACTION, (ACTION_DIM,))},
        "horizon": 16,
        "n_action_steps": 8,
        "n_obs_steps": 2,
        "noise_scheduler_type": "DDIM",
        "num_inference_steps": profile.inference_steps,
        "device": device,
        "push_to_hub": False,
    }
    if name == "omnid":
        from lerobot_omnid.policy.configuration_omnid import OmniDConfig
        from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

        calibration = {k: synthetic_calibration(i, size) for i, k in enumerate(keys)}
        config = OmniDConfig(**common, camera_calibration=calibration, **profile.omnid)
        return OmniDPolicy(config)
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy

    # Stock defaults except what cannot differ in a fair comparison: no downloadable weights, no crop
    # (OmniD does not crop), GroupNorm like OmniD's default.
    config = DiffusionConfig(
        **common, pretrained_backbone_weights=None, crop_shape=None, use_group_norm=True, **profile.diffusion
    )
    return DiffusionPolicy(config)


def measure(name: str, profile: Profile, device: str, repeats: int, queue: mp.Queue) -> None:
    """Runs in a fresh process: train step time, select_action latency, peak memory of one policy."""
    torch.manual_seed(0)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # MiB on Linux
    policy = build_policy(name, profile, device).to(device)
    n_params = sum(p.numel() for p in policy.parameters())
    batch = synthetic_batch(profile, device)
    optimizer = torch.optim.AdamW(policy.parameters(), lr=1e-4)

    def sync() -> None:
        if device == "cuda":
            torch.cuda.synchronize()

    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    policy.train()
    step_times = []
    for i in tqdm(range(repeats + 1), desc=f"{name}: train steps", leave=False):
        sync()
        start = time.perf_counter()
        loss, _ = policy.forward(batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        sync()
        if i > 0:  # the first step warms up allocators and kernels
            step_times.append(time.perf_counter() - start)
    train_peak = (
        torch.cuda.max_memory_allocated() / 2**20
        if device == "cuda"
        else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - rss_before
    )

    policy.eval()
    obs = {k: v[:1, -1] for k, v in batch.items() if k.startswith("observation.")}
    latencies = []
    for i in tqdm(range(repeats + 1), desc=f"{name}: select_action", leave=False):
        policy.reset()  # empty action queue: every call runs the full denoising loop
        sync()
        start = time.perf_counter()
        policy.select_action(obs)
        sync()
        if i > 0:
            latencies.append(time.perf_counter() - start)
    queue.put(
        {
            "policy": name,
            "params_M": n_params / 1e6,
            "train_step_s": statistics.median(step_times),
            "select_action_s": statistics.median(latencies),
            "train_peak_MiB": train_peak,
        }
    )


def synthetic_batch(profile: Profile, device: str) -> dict[str, torch.Tensor]:
    """A training batch of the profile's size: 4 cameras, 2 observation steps, horizon 16."""
    B, T, size = profile.batch_size, 2, profile.image_size
    batch = {f"observation.images.{c}": torch.rand(B, T, 3, size, size, device=device) for c in CAMERAS}
    batch["observation.state"] = torch.randn(B, T, STATE_DIM, device=device)
    batch["action"] = torch.randn(B, 16, ACTION_DIM, device=device)
    batch["action_is_pad"] = torch.zeros(B, 16, dtype=torch.bool, device=device)
    return batch


def alternating_steps(base: Profile, overrides: dict, device: str, steps: int) -> dict[str, float]:
    """Median training-step time of the profile's OmniD (A) and of it with ``overrides`` (B), their steps
    alternating in this process, who goes first alternating too."""
    variant = Profile(base.image_size, base.batch_size, {**base.omnid, **overrides}, base.diffusion)
    torch.manual_seed(0)
    policies = {
        "A (profile)": build_policy("omnid", base, device),
        f"B {overrides}": build_policy("omnid", variant, device),
    }
    batch = synthetic_batch(base, device)
    optimizers = {
        name: torch.optim.AdamW(p.to(device).train().parameters(), lr=1e-4) for name, p in policies.items()
    }
    times: dict[str, list[float]] = {name: [] for name in policies}
    for i in tqdm(range(steps + 1), desc="alternating train steps"):
        order = list(policies.items())
        for name, policy in order if i % 2 else order[::-1]:
            if device == "cuda":
                torch.cuda.synchronize()
            start = time.perf_counter()
            loss, _ = policy.forward(batch)
            optimizers[name].zero_grad()
            loss.backward()
            optimizers[name].step()
            if device == "cuda":
                torch.cuda.synchronize()
            if i > 0:  # the first step warms up allocators and kernels
                times[name].append(time.perf_counter() - start)
    return {name: statistics.median(t) for name, t in times.items()}


def parse_overrides(parser: argparse.ArgumentParser, option: str, items: list[str]) -> dict:
    overrides = {}
    for item in items:
        field, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            overrides[field] = json.loads(value)
        except ValueError:
            parser.error(f"{option}: expected FIELD=JSON, got {item!r}")
    return overrides


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--profile", choices=sorted(PROFILES), default="cpu")
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--repeats", type=int, default=3, help="measured repetitions after one warm-up")
    parser.add_argument("--policies", default="omnid,diffusion")
    parser.add_argument("--json", help="also write the results to this file")
    parser.add_argument(
        "--omnid",
        action="append",
        default=[],
        metavar="FIELD=JSON",
        help="override an OmniDConfig field, e.g. --omnid checkpoint_backbone=true (repeatable)",
    )
    parser.add_argument(
        "--against",
        action="append",
        default=[],
        metavar="FIELD=JSON",
        help="time OmniD with these OmniDConfig fields against the profile's OmniD (steps alternating)",
    )
    parser.add_argument(
        "--report-only", metavar="JSON", help="measure nothing: print the table of a --json file"
    )
    args = parser.parse_args()
    if args.report_only:
        try:
            summary = read_run_summary(Path(args.report_only), PROTOCOL)
        except ValueError as e:
            parser.error(f"--report-only: {e}")
        print(f"profile={summary.settings['profile']} device={summary.settings['device']}")
        print("\n".join(report_lines(summary.results["policies"])))
        return

    base = PROFILES[args.profile]
    overrides = parse_overrides(parser, "--omnid", args.omnid)
    if args.against:
        against = parse_overrides(parser, "--against", args.against)
        medians = alternating_steps(base, against, args.device, args.repeats)
        print(f"profile={args.profile} device={args.device} image={base.image_size} batch={base.batch_size}")
        for name, median in medians.items():
            print(f"{name:50s} train step {median:7.3f} s (median of {args.repeats})")
        a, b = medians.values()
        print(f"ratio B / A: {b / a:.2f}")
        return
    profile = Profile(
        base.image_size, base.batch_size, {**base.omnid, **overrides}, base.diffusion, base.inference_steps
    )
    print(
        f"profile={args.profile} device={args.device} cameras={len(CAMERAS)} image={profile.image_size}x"
        f"{profile.image_size} batch={profile.batch_size} obs_steps=2 horizon=16 "
        f"DDIM steps={profile.inference_steps} repeats={args.repeats} omnid overrides={overrides or 'none'}"
    )
    ctx = mp.get_context("spawn")
    results = []
    for name in args.policies.split(","):
        queue = ctx.Queue()
        proc = ctx.Process(target=measure, args=(name, profile, args.device, args.repeats, queue))
        proc.start()
        proc.join()
        if proc.exitcode != 0:
            raise SystemExit(f"{name}: measurement process failed with exit code {proc.exitcode}")
        results.append(queue.get())

    print("\n".join(report_lines(results)))
    if args.json:
        settings = {"profile": args.profile, "device": args.device, "repeats": args.repeats}
        command = ["python", "benchmarks/bench_policy.py", *sys.argv[1:]]
        write_run_summary(
            Path(args.json), RunSummary(PROTOCOL, settings, results={"policies": results}, command=command)
        )


def report_lines(results: list[dict]) -> list[str]:
    """The table of a run (its ``--json`` file): per policy parameters, median training step and
    ``select_action`` time, peak training memory; the ratios of the first policy to the second."""
    lines = [f"{'policy':<10} {'params':>9} {'train step':>11} {'select_action':>14} {'train peak mem':>15}"]
    for r in results:
        lines.append(
            f"{r['policy']:<10} {r['params_M']:>8.1f}M {r['train_step_s']:>10.3f}s "
            f"{r['select_action_s']:>13.3f}s {r['train_peak_MiB']:>11.0f} MiB"
        )
    if len(results) == 2:
        a, b = results
        lines.append(
            f"ratio {a['policy']}/{b['policy']}: train step {a['train_step_s'] / b['train_step_s']:.2f}x, "
            f"select_action {a['select_action_s'] / b['select_action_s']:.2f}x, "
            f"peak memory {a['train_peak_MiB'] / b['train_peak_MiB']:.2f}x"
        )
    return lines


if __name__ == "__main__":
    main()
