"""``omnid-sim-calibration``: write the calibration file of the sim robot's cameras.

The sim's cameras are calibrated exactly (``gym_omnid`` converts each MuJoCo camera to OmniD's OpenCV
convention, ``env.camera_calibration``); this command writes them in the schema of
:mod:`lerobot_omnid.calibration.rig_file`, keyed by the robot's camera names, for the images the robot
returns. It is the file a user of a real rig writes with ``omnid-calibrate``, and goes the same way:
``omnid-attach-calibration --calibration <file>`` attaches it to a dataset ``lerobot-record`` recorded.

Takes the ``--robot.*`` flags of ``lerobot-record`` (only ``--robot.type=omnid_sim``)::

    omnid-sim-calibration --robot.type=omnid_sim \\
        --robot.cameras='{front: {source: cam_b, width: 64, height: 64}}' --output=sim_rig.yaml
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import draccus
from lerobot.robots.config import RobotConfig

from lerobot_omnid.calibration.rig_file import save_calibration_file
from lerobot_omnid.keys import image_key
from lerobot_omnid.robot.config_omnid_sim import ROBOT_TYPE, OmniDSimConfig
from lerobot_omnid.robot.omnid_sim import OmniDSim


@dataclass
class SimCalibrationConfig:
    """Args:
    robot: The sim robot, with the same ``--robot.*`` flags as for ``lerobot-record``
        (``--robot.type=omnid_sim``; its cameras and their image size matter, the scene does not).
    output: The calibration file to write: YAML for ``.yaml`` / ``.yml``, JSON otherwise.
    """

    robot: RobotConfig
    output: Path = Path("sim_rig.yaml")


def export_sim_calibration(config: OmniDSimConfig, output: str | Path) -> Path:
    """Build the sim robot of ``config``, read its cameras' calibrations and write them to ``output``."""
    robot = OmniDSim(config)
    robot.connect()
    try:
        calibrations = {image_key(name): robot.camera_calibration(name) for name in robot.cameras}
    finally:
        robot.disconnect()
    meta = {
        image_key(name): {"source": f"gym_omnid camera {cam.source}, exact (simulation)"}
        for name, cam in config.cameras.items()
    }
    return save_calibration_file(output, calibrations, meta=meta)


def main(argv: Sequence[str] | None = None) -> int:
    cfg = draccus.parse(config_class=SimCalibrationConfig, args=list(sys.argv[1:] if argv is None else argv))
    if not isinstance(cfg.robot, OmniDSimConfig):
        print(
            f"omnid-sim-calibration: --robot.type: expected {ROBOT_TYPE}, got {cfg.robot.type}; a real rig's "
            f"calibration comes from omnid-calibrate (docs/calibration.md)",
            file=sys.stderr,
        )
        return 2
    path = export_sim_calibration(cfg.robot, cfg.output)
    height, width = cfg.robot.image_size
    print(
        f"Wrote the calibration of {len(cfg.robot.cameras)} camera(s) "
        f"({', '.join(cfg.robot.cameras)}) at {width}x{height} pixels to {path}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
