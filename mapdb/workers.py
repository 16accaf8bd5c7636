"""Worker processes: the one way toploc starts a process pool (map builds, evaluations).

Every pool is started with the *spawn* method, never *fork*: the parent has usually imported
OpenCV, whose thread pool is running, and a forked child inherits the locks those threads held
but not the threads, so it can deadlock on its first OpenCV call. A spawned child starts a fresh
interpreter and imports what it needs, so the work submitted to the pool must be picklable (a
module-level function, or a ``functools.partial`` of one).
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor


def spawn_process_pool(max_workers: int) -> ProcessPoolExecutor:
    """A ``ProcessPoolExecutor`` of ``max_workers`` (>= 1) processes started with *spawn*.

    Spawn, not fork: a fork after OpenCV started its threads can hang the child (see the module
    docstring). Raises ``ValueError`` for ``max_workers < 1``.
    """
    if max_workers < 1:
        raise ValueError(f"max_workers must be at least 1, got {max_workers}")
    return ProcessPoolExecutor(max_workers, mp_context=multiprocessing.get_context("spawn"))
