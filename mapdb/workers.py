"""Worker processes: the one way toploc starts a process pool (map builds, evaluations).

Every pool is started with the *spawn* method, never *fork*: the parent has usually imported
OpenCV, whose thread pool is running, and a forked child inherits the locks those threads held
but not the threads, so it can deadlock on its first OpenCV call. A spawned child starts a fresh
interpreter and imports what it needs, so the work submitted to the pool must be picklable (a
module-level function, or a ``functools.partial`` of one).

Workers die with their parent, ``kill -9`` included: on Linux the kernel sends them ``SIGKILL``
when the parent ends (``prctl(PR_SET_PDEATHSIG)``), and on every system a watcher thread in each
worker ends it once its parent pid changes (the parent is gone, the worker was re-parented).
Linux counts the *thread* that started a worker as its parent, and a ``ProcessPoolExecutor``
starts workers in the thread that calls ``submit``: submit from a thread that outlives the pool
(the main thread, as every caller does).
Workers ignore ``SIGINT`` and ``SIGTERM``: Ctrl-C in a terminal, and a service manager's stop,
reach the whole process group, and the parent alone decides what an interrupt means (it stops
the pool, see :func:`stop_workers`).

A worker that dies while the pool runs (the kernel's out-of-memory killer, a ``kill -9``, a
crash in OpenCV) is noticed by :meth:`WorkerPool.check_workers`, which the caller's wait loop
calls between two waits (:func:`results_in_order` does): the pool is stopped and
:class:`WorkerDiedError` names the worker and how it ended. The pool itself notices a dead
worker only when it is not reading a result: one killed half-way through sending its result
leaves every future pending for ever (see :func:`stop_workers`).
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from types import FrameType, TracebackType
from typing import TypeVar

T = TypeVar("T")

PR_SET_PDEATHSIG = 1
"""``prctl`` option: the signal the kernel sends a process when its parent ends (Linux)."""

PARENT_POLL_S = 0.2
"""How often a worker's watcher thread checks that its parent is still alive, seconds."""

RESULT_POLL_S = 0.5
"""How long :func:`results_in_order` waits for a result before it checks the workers, seconds."""


class WorkerDiedError(BrokenProcessPool):
    """A pool worker ended while the pool was running; the pool has been stopped.

    ``pid`` and ``exitcode`` are the worker's (a negative exit code is the signal that ended it,
    as in :attr:`multiprocessing.Process.exitcode`).
    """

    def __init__(self, pid: int, exitcode: int) -> None:
        self.pid, self.exitcode = pid, exitcode
        super().__init__(f"process {pid} {describe_exit(exitcode)}")


def describe_exit(exitcode: int) -> str:
    """How a process with this :attr:`~multiprocessing.Process.exitcode` ended, in words."""
    if exitcode >= 0:
        return f"exited with status {exitcode}"
    try:
        name = signal.Signals(-exitcode).name
    except ValueError:
        name = f"signal {-exitcode}"
    if -exitcode == signal.SIGKILL:
        return f"was killed by {name} (the out-of-memory killer, or a kill -9)"
    return f"was ended by {name}"


def _set_parent_death_signal() -> None:
    """Ask the Linux kernel to ``SIGKILL`` this process when its parent ends (no-op elsewhere)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass  # the watcher thread still ends the worker


def _watch_parent(parent_pid: int, poll_s: float) -> None:
    """End this process at once when its parent is no longer ``parent_pid``."""
    while os.getppid() == parent_pid:
        time.sleep(poll_s)
    os._exit(1)


def init_worker(parent_pid: int) -> None:
    """Initializer of every pool worker: die with the parent, leave Ctrl-C and SIGTERM to it.

    ``parent_pid`` is the pool owner's pid, read before the worker started: a parent that died
    before this runs is noticed too.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _set_parent_death_signal()
    if os.getppid() != parent_pid:
        os._exit(1)
    watcher = threading.Thread(
        target=_watch_parent, args=(parent_pid, PARENT_POLL_S), name="parent-watch", daemon=True
    )
    watcher.start()


def stop_workers(pool: ProcessPoolExecutor) -> None:
    """Stop ``pool`` now: cancel what is queued and kill the workers mid-task (results lost).

    For an interrupt or an error, when nothing more is wanted from the pool; the workers are
    reaped by the pool's own thread (at the latest at interpreter exit).

    A worker killed while it sends a result leaves half a message in the result pipe (above
    16 KiB, ``Connection.send_bytes`` writes the length and the payload in two writes). The
    pool's manager thread then waits in ``recv()`` for bytes that never come, and the
    interpreter joins that thread at exit for ever: the build that printed "interrupted" and
    never exited (py-spy: the thread in ``Connection._recv``, reading the 26,135 bytes of a
    result whose length it had read). Only the last writer's close ends that read, and this
    process holds a writer too (to hand it to new workers): closed once the workers are killed,
    the read sees end of file when they are gone, and the manager thread takes the pool for
    broken, reaps the workers and ends.
    """
    processes = dict(getattr(pool, "_processes", None) or {})
    result_queue = getattr(pool, "_result_queue", None)  # shutdown() forgets it
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes.values():
        try:
            process.kill()
        except (ProcessLookupError, ValueError):
            continue  # already gone, or already closed
    writer = getattr(result_queue, "_writer", None)
    if writer is not None:
        writer.close()  # after shutdown() no worker is started (no max_tasks_per_child)


class WorkerPool(ProcessPoolExecutor):
    """A spawned ``ProcessPoolExecutor`` whose ``with`` block kills its workers on an error or
    interrupt instead of waiting for every queued task, and that can tell when a worker died
    (:meth:`check_workers`)."""

    def check_workers(self) -> None:
        """Raise :class:`WorkerDiedError` if a worker has ended, after stopping the pool.

        Call it while results are awaited: workers end only at shutdown (the pool starts no
        replacement and none retires after some tasks), so an ended worker means one died, and
        the pool may never say so itself (a result half sent, see :func:`stop_workers`).
        """
        for pid, exitcode in self._ended():
            stop_workers(self)
            raise WorkerDiedError(pid, exitcode)

    def named(self, error: BrokenProcessPool) -> BrokenProcessPool:
        """``error`` as a :class:`WorkerDiedError` naming the worker that ended, when the pool
        noticed it first and said only "A child process terminated abruptly" (which of the two
        notices first is a race); ``error`` itself if it names one already or none has ended
        within a second. The pool terminates the other workers once it finds one ended: a
        worker not ended by ``SIGTERM`` is the one that died."""
        if isinstance(error, WorkerDiedError):
            return error
        ended = self._ended()
        deadline = time.monotonic() + 1.0
        while not ended and time.monotonic() < deadline:
            # The pool's own thread may be reaping the worker this moment: one thread reads its
            # exit status, and another asking meanwhile sees none yet. Let that thread finish.
            time.sleep(0.01)
            ended = self._ended()
        died = [(pid, code) for pid, code in ended if code != -signal.SIGTERM] or ended
        return WorkerDiedError(*died[0]) if died else error

    def _ended(self) -> list[tuple[int, int]]:
        """The (pid, exit code) of each worker that has ended."""
        processes = dict(getattr(self, "_processes", None) or {})
        ended = ((pid, process.exitcode) for pid, process in processes.items())
        return [(pid, code) for pid, code in ended if code is not None]

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc_val: BaseException | None,
        exc_tb: TracebackType | None,
    ) -> bool | None:
        if exc_type is not None:
            stop_workers(self)
        return super().__exit__(exc_type, exc_val, exc_tb)


def spawn_process_pool(max_workers: int) -> WorkerPool:
    """A process pool of ``max_workers`` (>= 1) workers started with *spawn*.

    Spawn, not fork: a fork after OpenCV started its threads can hang the child (see the module
    docstring). The workers die with this process and ignore Ctrl-C (:func:`init_worker`).
    Raises ``ValueError`` for ``max_workers < 1``.
    """
    if max_workers < 1:
        raise ValueError(f"max_workers must be at least 1, got {max_workers}")
    return WorkerPool(
        max_workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=init_worker,
        initargs=(os.getpid(),),
    )


def results_in_order(pool: WorkerPool, futures: Sequence[Future[T]]) -> Iterator[T]:
    """Each future's result, in the order given, checking the workers between waits of
    :data:`RESULT_POLL_S`: :class:`WorkerDiedError` when one died, instead of waiting for ever.
    An exception raised by the task itself is raised as :meth:`Future.result` raises it."""
    for future in futures:
        while True:
            try:
                result = future.result(timeout=RESULT_POLL_S)
            except TimeoutError:
                pool.check_workers()
                continue
            yield result
            break


@contextmanager
def deferred_signals(
    signums: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM),
) -> Iterator[Callable[[], None]]:
    """Within the block, ``signums`` are only noted; the ``check()`` it yields runs the handler
    they would have run (for Ctrl-C: raise ``KeyboardInterrupt``) where the caller calls it.

    Why: a handler that raises can raise in the middle of ``concurrent.futures``' own code, e.g.
    between a lock's acquire and the ``try`` that releases it. A lock left held blocks the pool's
    manager thread, and the interpreter waits for that thread at exit for ever. Raising only
    from the caller's loop keeps the exception out of library code. (The build seen in CI to
    print "interrupted" and never exit was another case: a half-sent result, see
    :func:`stop_workers`.)

    A signal noted after the last ``check()`` runs its handler when the block ends, also when
    it ends by an error (a signal that broke something is still the signal: Ctrl-C, not the
    error it caused, is what the user is told).
    The first noted signal puts the handlers back, so a second Ctrl-C acts at once (a call
    that does not return must not keep the program). Signals whose handler is not a Python
    function (``SIG_DFL``, ``SIG_IGN``) are left alone, and so is everything outside the main
    thread, where handlers cannot be set.
    """
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    pending: list[int] = []
    previous: dict[int, Callable[[int, FrameType | None], object]] = {}

    def restore() -> None:
        for signum, handler in previous.items():
            signal.signal(signum, handler)

    def note(signum: int, _frame: FrameType | None) -> None:
        pending.append(signum)
        restore()

    def check() -> None:
        if pending:
            signum = pending[0]
            pending.clear()
            previous[signum](signum, None)

    for signum in signums:
        handler = signal.getsignal(signum)
        if callable(handler):
            previous[signum] = handler
            signal.signal(signum, note)
    try:
        yield check
    finally:
        restore()
        check()
