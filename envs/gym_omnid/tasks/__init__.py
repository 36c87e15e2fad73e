"""One module per task; :func:`make_task` builds a fresh task instance by name."""

from __future__ import annotations

from gym_omnid.tasks.base import Task
from gym_omnid.tasks.select_apple import SelectApple
from gym_omnid.tasks.select_chemistry_tube import SelectChemistryTube

TASK_CLASSES: tuple[type[Task], ...] = (SelectApple, SelectChemistryTube)


def make_task(name: str) -> Task:
    """A new :class:`Task` instance for ``name`` (one of ``gym_omnid.TASKS``)."""
    for cls in TASK_CLASSES:
        if cls.name == name:
            return cls()
    raise ValueError(f"task: expected one of {[cls.name for cls in TASK_CLASSES]}, got {name!r}")


__all__ = ["TASK_CLASSES", "Task", "make_task"]
