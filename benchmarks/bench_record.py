"""Recorder throughput: frames per second of ``omnid-record`` with streaming video encoding (ours) vs
LeRobot's default path (PNG files per frame, encoded when the episode is saved), side by side.

    python benchmarks/bench_record.py                       # 5 episodes, five cameras at 128x128
    python benchmarks/bench_record.py --episodes 10 --image-size 256 --repeats 2

Both variants record the same seeds (hence the same frames) into fresh temporary directories; the
order of the variants alternates between repeats. Wall time covers the whole recording (env stepping,
rendering, encoding, statistics, finalising), not the process start-up. On a shared machine the
absolute numbers move with the load; the ratio measured in one run is the claim.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

from gym_omnid.constants import CAMERAS

from lerobot_omnid.record import quiet_third_party_logs, record_dataset

VARIANTS = {"streaming (omnid-record)": True, "PNG then encode (LeRobot default)": False}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--image-size", type=int, default=128)
    parser.add_argument("--cameras", default=",".join(CAMERAS))
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    quiet_third_party_logs()

    fps: dict[str, list[float]] = {name: [] for name in VARIANTS}
    frames = 0
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(args.repeats):
            names = list(VARIANTS) if repeat % 2 == 0 else list(reversed(VARIANTS))
            for name in names:
                summary = record_dataset(
                    Path(tmp) / f"{repeat}_{VARIANTS[name]}",
                    episodes=args.episodes,
                    cameras=args.cameras.split(","),
                    image_size=args.image_size,
                    streaming_encoding=VARIANTS[name],
                    show_progress=False,
                )
                frames = summary.frames
                fps[name].append(summary.frames_per_s)
                print(f"  {name}: {summary.line()}")

    size = f"{args.image_size}x{args.image_size}"
    print(
        f"\n{args.episodes} episodes ({frames} frames), {args.cameras} at {size}, "
        f"median of {args.repeats} repeat(s):"
    )
    medians = {name: statistics.median(values) for name, values in fps.items()}
    baseline = medians["PNG then encode (LeRobot default)"]
    for name, value in medians.items():
        print(f"  {name:36s} {value:7.1f} frames/s   x{value / baseline:.2f}")


if __name__ == "__main__":
    main()
