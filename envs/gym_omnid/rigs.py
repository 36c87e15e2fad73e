"""Camera rigs: named placements of the five fixed cameras, chosen with the env option ``rig``.

``default`` is the benchmark's rig (``gym_omnid.scene.CAMERA_POSES``). The others stand for the same
cameras rebuilt in another lab or bumped: every camera moves by 8-17 cm and turns by 5-14 degrees from
its default placement, and each still sees the whole workspace (``WORKSPACE_BOUNDS``) but its corners
(tested):

- ``closer``: every camera 8-13 cm nearer the table and shifted sideways, with a few degrees of roll;
- ``higher``: every camera 12-16 cm higher and tilted further down;
- ``bumped``: every camera pushed 9-12 cm in its own direction and rolled 7-10 degrees.

Only the five fixed cameras move; the wrist camera rides on the gripper in every rig.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from gym_omnid.constants import CAMERAS, DEFAULT_RIG
from gym_omnid.scene import CAMERA_POSES, CameraPlacement

RIG_PLACEMENTS: Mapping[str, Mapping[str, CameraPlacement]] = MappingProxyType(
    {
        DEFAULT_RIG: MappingProxyType({cam: CameraPlacement(*CAMERA_POSES[cam]) for cam in CAMERAS}),
        "closer": MappingProxyType(
            {
                "cam_a": CameraPlacement((0.36, -0.23, 1.08), (0.55, 0.03, 0.0), 3.0),
                "cam_b": CameraPlacement((1.29, 0.06, 0.55), (0.52, 0.0, 0.05), -6.0),
                "cam_c": CameraPlacement((0.60, 0.74, 0.50), (0.50, 0.0, 0.05), 4.0),
                "cam_d": CameraPlacement((0.49, -0.73, 0.54), (0.57, 0.0, 0.05), -3.0),
                "cam_e": CameraPlacement((-0.04, 0.56, 0.59), (0.55, -0.03, 0.05), -5.0),
            }
        ),
        "higher": MappingProxyType(
            {
                "cam_a": CameraPlacement((0.24, -0.32, 1.30), (0.58, -0.05, 0.0), -4.0),
                "cam_b": CameraPlacement((1.39, -0.05, 0.70), (0.54, 0.0, 0.03), 0.0),
                "cam_c": CameraPlacement((0.50, 0.85, 0.68), (0.54, 0.0, 0.02), 2.0),
                "cam_d": CameraPlacement((0.61, -0.85, 0.66), (0.52, 0.0, 0.03), -2.0),
                "cam_e": CameraPlacement((-0.16, 0.65, 0.75), (0.55, 0.03, 0.02), 3.0),
            }
        ),
        "bumped": MappingProxyType(
            {
                "cam_a": CameraPlacement((0.37, -0.22, 1.18), (0.55, 0.0, 0.0), -9.0),
                "cam_b": CameraPlacement((1.38, -0.09, 0.50), (0.52, -0.05, 0.05), 8.0),
                "cam_c": CameraPlacement((0.46, 0.78, 0.58), (0.51, 0.0, 0.05), -7.0),
                "cam_d": CameraPlacement((0.63, -0.79, 0.47), (0.54, 0.04, 0.05), 10.0),
                "cam_e": CameraPlacement((-0.07, 0.70, 0.56), (0.55, 0.0, 0.05), -8.0),
            }
        ),
    }
)
"""Rig name -> camera name -> placement, for every name in ``RIGS`` (same order)."""
