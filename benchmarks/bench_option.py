"""Training-step time of OmniD with and without one option, measured side by side in one process.

The two policies' steps alternate (A B, B A, A B, ...), so a busy machine slows both alike and the printed
ratio stays meaningful where absolute times do not (e.g. on 2 shared CPU cores).

    python benchmarks/bench_option.py --set fuse_last_step_only=true          # the cpu profile
    python benchmarks/bench_option.py --set fuse_last_step_only=true --profile paper --device cuda
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import torch
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).parent))
from bench_policy import ACTION_DIM, CAMERAS, PROFILES, STATE_DIM, Profile, build_policy


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--set", action="append", required=True, help="OmniDConfig FIELD=JSON of variant B")
    parser.add_argument("--profile", choices=sorted(PROFILES), default="cpu")
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--steps", type=int, default=5, help="measured steps per variant after one warm-up")
    args = parser.parse_args()
    overrides = {}
    for item in args.set:
        field, _, value = item.partition("=")
        try:
            overrides[field] = json.loads(value)
        except json.JSONDecodeError:
            parser.error(f"--set: expected FIELD=JSON, got {item!r}")
    base = PROFILES[args.profile]
    variant = Profile(base.image_size, base.batch_size, {**base.omnid, **overrides}, base.diffusion)
    torch.manual_seed(0)
    policies = {
        "A (profile)": build_policy("omnid", base, args.device),
        f"B {overrides}": build_policy("omnid", variant, args.device),
    }
    B, T, size = base.batch_size, 2, base.image_size
    batch = {f"observation.images.{c}": torch.rand(B, T, 3, size, size, device=args.device) for c in CAMERAS}
    batch["observation.state"] = torch.randn(B, T, STATE_DIM, device=args.device)
    batch["action"] = torch.randn(B, 16, ACTION_DIM, device=args.device)
    batch["action_is_pad"] = torch.zeros(B, 16, dtype=torch.bool, device=args.device)
    times: dict[str, list[float]] = {name: [] for name in policies}
    optimizers = {
        name: torch.optim.AdamW(p.to(args.device).train().parameters(), lr=1e-4)
        for name, p in policies.items()
    }
    for i in tqdm(range(args.steps + 1), desc="alternating train steps"):
        order = list(policies.items())
        for name, policy in order if i % 2 else order[::-1]:  # who goes first alternates too
            if args.device == "cuda":
                torch.cuda.synchronize()
            start = time.perf_counter()
            loss, _ = policy.forward(batch)
            optimizers[name].zero_grad()
            loss.backward()
            optimizers[name].step()
            if args.device == "cuda":
                torch.cuda.synchronize()
            if i > 0:
                times[name].append(time.perf_counter() - start)
    print(f"profile={args.profile} device={args.device} image={size}x{size} batch={B} cameras={len(CAMERAS)}")
    medians = {name: statistics.median(t) for name, t in times.items()}
    for name, median in medians.items():
        print(f"{name:50s} train step {median:7.3f} s (median of {args.steps})")
    a, b = medians.values()
    print(f"ratio B / A: {b / a:.2f}")


if __name__ == "__main__":
    main()
