"""Copy a LeRobot checkpoint with other cameras as its image inputs, to fine-tune it on a new view.

``lerobot-train --policy.path=<checkpoint>`` keeps the checkpoint's ``input_features``, and a
``--policy.input_features=...`` override is merged into them rather than replacing them, so a stock policy
trained on cameras B-E would still ask for B-E when fine-tuned on a camera-A dataset. This writes a copy of
the checkpoint whose ``config.json`` lists the state and the new cameras' images instead (same image shape
as the old ones); weights and processors are copied unchanged. It suits policies whose weights do not depend
on the number or identity of cameras (LeRobot's ACT, and VQ-BeT with its one image). OmniD needs none of
this: ``--policy.cameras`` selects its cameras.

    python -m lerobot_omnid.benchmark.checkpoint_cameras \
        --src <pretrained_model> --dst <folder> --cameras cam_a
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from lerobot_omnid.keys import IMAGE_KEY_PREFIX, image_key

CONFIG = "config.json"


def retarget_cameras(src: Path, dst: Path, cameras: list[str]) -> Path:
    """Write the copy at ``dst`` (replacing it); returns ``dst``. The new config is written last, so a
    ``dst`` with a ``config.json`` is complete."""
    config = json.loads((src / CONFIG).read_text())
    features = config.get("input_features") or {}
    images = [ft for key, ft in features.items() if key.startswith(IMAGE_KEY_PREFIX)]
    if not images:
        raise ValueError(
            f"{src / CONFIG}: input_features has no {IMAGE_KEY_PREFIX}* entry to take the shape from"
        )
    if not cameras or len(set(cameras)) != len(cameras):
        raise ValueError(f"cameras: expected distinct camera names, got {cameras}")
    others = {key: ft for key, ft in features.items() if not key.startswith(IMAGE_KEY_PREFIX)}
    config["input_features"] = {**others, **{image_key(cam): dict(images[0]) for cam in cameras}}
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns(CONFIG))
    (dst / CONFIG).write_text(json.dumps(config, indent=4) + "\n")
    return dst


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--src", type=Path, required=True, help="a checkpoint's pretrained_model folder")
    parser.add_argument("--dst", type=Path, required=True, help="folder of the copy (replaced)")
    parser.add_argument("--cameras", required=True, help="comma-separated cameras, e.g. cam_a")
    args = parser.parse_args(argv)
    if not (args.src / CONFIG).is_file():
        parser.error(f"--src: expected a checkpoint folder with {CONFIG}, got {args.src}")
    try:
        retarget_cameras(args.src, args.dst, [c.strip() for c in args.cameras.split(",") if c.strip()])
    except ValueError as e:
        parser.error(str(e))
    print(f"{args.dst}: inputs {', '.join(json.loads((args.dst / CONFIG).read_text())['input_features'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
