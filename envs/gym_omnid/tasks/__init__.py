"""One module per task; :func:`make_task` builds a fresh task instance by name."""

from __future__ import annotations

import numpy as np

from gym_omnid.constants import TASK_ONEHOT_NAMES
from gym_omnid.tasks.add_condiment import AddCondiment
from gym_omnid.tasks.base import Task
from gym_omnid.tasks.get_coffee import GetCoffee
from gym_omnid.tasks.select_apple import SelectApple
from gym_omnid.tasks.select_chemistry_tube import SelectChemistryTube
from gym_omnid.tasks.set_study_table import SetStudyTable
from gym_omnid.tasks.texas_holdem import TexasHoldem

TASK_CLASSES: tuple[type[Task], ...] = (
    SelectApple,
    SelectChemistryTube,
    AddCondiment,
    GetCoffee,
    SetStudyTable,
    TexasHoldem,
)


def make_task(name: str) -> Task:
    """A new :class:`Task` instance for ``name`` (one of ``gym_omnid.TASKS``)."""
    for cls in TASK_CLASSES:
        if cls.name == name:
            return cls()
    raise ValueError(f"task: expected one of {[cls.name for cls in TASK_CLASSES]}, got {name!r}")


def task_onehot(name: str) -> np.ndarray:
    """(len(TASK_ONEHOT_NAMES),) float32: 1 at the index of task ``name`` in ``TASK_ONEHOT_NAMES``, else 0."""
    if name not in TASK_ONEHOT_NAMES:
        raise ValueError(f"task: expected one of {list(TASK_ONEHOT_NAMES)}, got {name!r}")
    onehot = np.zeros(len(TASK_ONEHOT_NAMES), dtype=np.float32)
    onehot[TASK_ONEHOT_NAMES.index(name)] = 1.0
    return onehot


__all__ = ["TASK_CLASSES", "Task", "make_task", "task_onehot"]
