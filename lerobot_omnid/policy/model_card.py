"""The OmniD part of a Hub model card: cameras, their calibration, the volume, evaluation results."""

from __future__ import annotations

import json
import math
from pathlib import Path

import torch

from lerobot_omnid.geometry import camera_centers_world
from lerobot_omnid.policy.configuration_omnid import OmniDConfig


def find_eval_results(output_dir: str | Path) -> dict[str, dict]:
    """``eval_info.json`` files written by ``lerobot-eval`` under ``output_dir``, by their folder name."""
    results = {}
    for path in sorted(Path(output_dir).glob("**/eval_info.json")):
        overall = json.loads(path.read_text()).get("overall", {})
        results[str(path.parent.relative_to(output_dir)) or "."] = overall
    return results


def omnid_card_section(config: OmniDConfig, eval_results: dict[str, dict]) -> str:
    """Markdown: cameras with intrinsics and position in the robot base frame, the feature volume, and
    the success rates of the evaluations found (or a note that none were run before the push)."""
    lines = ["", "## OmniD: cameras and calibration", ""]
    lines += [
        "World frame = robot base frame (x forward, y left, z up, metres). `T_cam_world` maps world points",
        "into the OpenCV camera frame; the full matrices are in `config.json` (`camera_calibration`).",
        "",
        "| camera | image (h x w) | fx | fy | cx | cy | position in base frame (m) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for key in config.image_features:
        if key in config.frame_calibration:  # a moving camera, or a dataset of several rigs
            lines.append(f"| `{key}` | calibrated per frame (`observation.extrinsics.*` columns) |||||")
            continue
        if key not in config.camera_calibration:  # the "w/o OFG" ablation needs none
            lines.append(f"| `{key}` | not calibrated |||||")
            continue
        calib = config.calibration(key)
        (fx, _, cx), (_, fy, cy), _ = calib.K
        centre = camera_centers_world(torch.tensor(calib.T_cam_world, dtype=torch.float64)).tolist()
        pos = ", ".join(f"{round(v, 3) + 0.0:.3f}" for v in centre)  # + 0.0: no "-0.000"
        h, w = calib.image_size
        lines.append(f"| `{key}` | {h} x {w} | {fx:.1f} | {fy:.1f} | {cx:.1f} | {cy:.1f} | ({pos}) |")
    volume = config.feature_volume
    lines += [
        "",
        f"Feature volume: bounds {list(map(list, volume.bounds))} m, {list(volume.shape)} cells, "
        f"pillars along `{volume.pillar_axis}`; backbone `{config.vision_backbone}`, OFG "
        f"{'on' if config.use_ofg else 'off (w/o OFG ablation)'}.",
        "",
        "## Evaluation",
        "",
    ]
    if not eval_results:
        lines.append("Not evaluated before this push.")
    else:
        lines += ["| evaluation | episodes | success rate (%) |", "| --- | --- | --- |"]
        for name, overall in eval_results.items():
            rate = overall.get("pc_success", math.nan)
            lines.append(f"| {name} | {overall.get('n_episodes', '?')} | {rate:.1f} |")
    return "\n".join(lines) + "\n"
