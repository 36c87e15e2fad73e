"""``--teleop.type=omnid_expert``: the scripted expert of ``gym_omnid`` as a LeRobot teleoperator, producing
the actions of ``--robot.type=omnid_sim``.

LeRobot finds the class by naming convention: ``OmniDExpertConfig`` here, ``OmniDExpert`` in the sibling
module ``omnid_expert``.
"""

from __future__ import annotations

from dataclasses import dataclass

from gym_omnid.constants import LAYOUTS, TASKS
from lerobot.teleoperators.config import TeleoperatorConfig

from lerobot_omnid.cli import check_choice
from lerobot_omnid.robot.config_omnid_sim import check_seed

TELEOP_TYPE = "omnid_expert"
"""The ``--teleop.type`` of the expert, also its ``Teleoperator.name``."""


@TeleoperatorConfig.register_subclass(TELEOP_TYPE)
@dataclass(kw_only=True)
class OmniDExpertConfig(TeleoperatorConfig):
    """The scripted expert that solves one ``gym_omnid`` scene.

    The expert plans from the scene's object poses right after its reset and then replays that plan
    open loop (``gym_omnid.experts``). LeRobot gives a teleoperator no access to the robot, so the expert
    rebuilds the same scene from the same ``task``, ``layout`` and ``seed`` (the reset is deterministic;
    cameras and table texture do not change it): **give it the values of** ``--robot.task``,
    ``--robot.layout`` and ``--robot.seed``. After the plan it holds its last action.

    Args:
        task: Benchmark task, one of ``gym_omnid.TASKS`` (the robot's).
        layout: ``"id"`` or ``"position_ood"`` (the robot's).
        seed: Reset seed of the scene (the robot's).
    """

    task: str = "select_apple"
    layout: str = "id"
    seed: int = 0

    def __post_init__(self) -> None:
        check_choice("task", self.task, TASKS)
        check_choice("layout", self.layout, LAYOUTS)
        check_seed("seed", self.seed)
