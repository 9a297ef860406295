"""The learning tasks, one class each (see :mod:`ectskin.learn.tasks.base`).

==========  ===================  ============================================================
``touch``   :class:`TouchTask`   touch class per calibrated frame (TouchMLP), Fig. 7
``track``   :class:`TrackTask`   marker coordinates from a window of frames (C2DT), Fig. 9/10
``contact`` :class:`ContactTask` finger count, points (mm), forces (N), hover (ContactNet)
==========  ===================  ============================================================

:func:`get_task` gives the task of a name (the ``task`` of ``ectskin train`` and config.json),
:func:`task_for_model` the task of a checkpoint's model kind.
"""

from __future__ import annotations

from ectskin._check import EctskinError, check_option
from ectskin.learn.tasks.base import Criterion, EvalCase, Task
from ectskin.learn.tasks.contact import ContactCriterion, ContactTask
from ectskin.learn.tasks.touch import TouchCriterion, TouchTask
from ectskin.learn.tasks.track import TrackCriterion, TrackTask

#: task name → task
TASKS: dict[str, Task] = {task.name: task for task in (TouchTask(), TrackTask(), ContactTask())}


def get_task(name: str) -> Task:
    """The task called ``name``; an unknown name is an error listing the tasks."""
    check_option("task", name, tuple(TASKS))
    return TASKS[name]


def task_for_model(kind: str) -> Task:
    """The task whose model has the checkpoint kind ``kind`` ("touch_mlp", "c2dt")."""
    for task in TASKS.values():
        if task.model_kind == kind:
            return task
    known = ", ".join(repr(t.model_kind) for t in TASKS.values())
    raise EctskinError(f"no task trains a {kind!r} model (known kinds: {known})")


__all__ = [
    "TASKS",
    "ContactCriterion",
    "ContactTask",
    "Criterion",
    "EvalCase",
    "Task",
    "TouchCriterion",
    "TouchTask",
    "TrackCriterion",
    "TrackTask",
    "get_task",
    "task_for_model",
]
