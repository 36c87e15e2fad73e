"""Calibration files for OmniD's controls (:mod:`lerobot_omnid.benchmark.controls`: blind, scrambled,
perturbed), the file a checkpoint is evaluated with.

``lerobot-eval --policy.path=<checkpoint> --policy.calibration_path=<file>`` replaces the checkpoint's
calibrations with a file's (read once when the config is made), so one trained OmniD is evaluated with a
calibration that lies. Written from the checkpoint's own ``config.json`` (its ``camera_calibration`` and
``volume_bounds``)::

    python -m lerobot_omnid.benchmark.control_calibration --checkpoint <pretrained_model> \
        --control blind --out <file.json>
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from lerobot_omnid.benchmark.controls import control_calibrations
from lerobot_omnid.benchmark.methods import CONTROLS
from lerobot_omnid.calibration.rig_file import save_calibration_file

CONFIG = "config.json"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--checkpoint", type=Path, required=True, help="an OmniD checkpoint's pretrained_model"
    )
    parser.add_argument("--control", choices=CONTROLS, required=True, help="which calibration to write")
    parser.add_argument("--out", type=Path, required=True, help="calibration file to write (JSON)")
    args = parser.parse_args(argv)
    config_path = args.checkpoint / CONFIG
    if not config_path.is_file():
        parser.error(f"--checkpoint: expected a checkpoint folder with {CONFIG}, got {args.checkpoint}")
    try:
        calibrations = control_calibrations(json.loads(config_path.read_text()), args.control)
    except ValueError as e:
        parser.error(f"{config_path}: {e}")
    save_calibration_file(args.out, calibrations)
    print(f"{args.out}: {args.control} calibration of {', '.join(calibrations)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
