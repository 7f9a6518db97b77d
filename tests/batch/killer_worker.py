"""A Dask worker preload for the tests: a bag whose name contains ``kills-its-worker`` ends the worker process
at once, as an out-of-memory kill or a crash in native code would (``dask worker --preload`` this module)."""

from __future__ import annotations

import os
from typing import Any


def dask_setup(worker: Any) -> None:
    from bagtools.batch import task as task_module

    run_task = task_module.run_task

    def crashing_run_task(task: task_module.BagTask) -> dict:
        if "kills-its-worker" in task.bag:
            os._exit(1)
        return run_task(task)

    crashing_run_task.__qualname__ = crashing_run_task.__name__ = "run_task"
    task_module.run_task = crashing_run_task  # the client's pickled reference resolves to this one
