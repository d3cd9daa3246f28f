"""Independent solves shared with one forked child process, on a machine with a second core.

:func:`map_forked` runs ``function`` over a list of items: this process takes the items at
even positions, a child forked from it (``os.fork``: it shares the parent's memory, nothing is
sent to it) takes the others and sends its outcomes back pickled through a pipe. The outcomes
are the same as those of a serial run, in the same order: each call must depend only on its
item (seeded randomness, no state shared between calls). A child that fails in any way
(fork refused, crash, an error that is not a :class:`~.errors.CalibrationError`) costs only
time: its items are then computed here. The child is always waited for (no zombie), and
killed when this process is interrupted.

Forking is unsafe in a process with other threads (a lock another thread holds stays locked
in the child, which may then wait forever: a ROS executor's, a middleware's), so it is off
unless asked for (``workers=2``; the command line asks for it, the nodes do not), and a
process that runs any other thread solves everything itself even then (:func:`alone`: the
command line runs one BLAS thread for that reason, :mod:`linelaser_calib.entry`).
"""

from __future__ import annotations

import os
import pickle
import signal
import threading
from collections.abc import Callable, Sequence
from typing import NoReturn, TypeVar

from .errors import CalibrationError

Item = TypeVar("Item")
Value = TypeVar("Value")

#: Processes a solve may use: this one and at most one child.
MAX_WORKERS = 2


def available_workers() -> int:
    """Processes worth using here: the cores this process may run on, at most
    :data:`MAX_WORKERS`."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    return max(1, min(MAX_WORKERS, cores))


def alone() -> bool:
    """True when this process runs no other thread: the operating system's count where
    ``/proc`` gives it (threads of C libraries included), else Python's."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Threads:"):
                    return int(line.split()[1]) == 1
    except OSError:
        pass
    return threading.active_count() == 1


def _outcome(function: Callable[[Item], Value], item: Item) -> Value | CalibrationError:
    """``function(item)``, or the CalibrationError it raised."""
    try:
        return function(item)
    except CalibrationError as exc:
        return exc


def _child(function: Callable[[Item], Value], items: Sequence[Item], pipe: int) -> NoReturn:
    """In the forked child: the outcomes of ``items`` pickled into ``pipe``, then exit at once
    (no cleanup of the parent's state: buffers, atexit handlers)."""
    status = 1
    try:
        data = pickle.dumps([_outcome(function, item) for item in items])
        with os.fdopen(pipe, "wb") as stream:
            stream.write(data)
        status = 0
    finally:
        os._exit(status)


def map_forked(
    function: Callable[[Item], Value],
    items: Sequence[Item],
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> list[Value | CalibrationError]:
    """``function`` of every item, or the CalibrationError it raised, in the items' order.

    Parameters
    ----------
    function : callable
        Deterministic given its item.
    items : sequence
    workers : int
        1 runs everything here; 2 shares the items with a forked child when this process
        runs no other thread (see the module docstring).
    progress : callable, optional
        ``progress(done, total)`` after each item this process finishes (with a child: the
        items both have finished, counting the child's pace as this one's).
    """
    total = len(items)

    def reported(k: int, item: Item, per_item: int) -> Value | CalibrationError:
        outcome = _outcome(function, item)
        if progress is not None:
            progress(min(per_item * (k + 1), total), total)
        return outcome

    if workers < 2 or len(items) < 2 or not hasattr(os, "fork") or not alone():
        return [reported(k, item, 1) for k, item in enumerate(items)]
    read, write = os.pipe()
    try:
        pid = os.fork()
    except OSError:
        os.close(read)
        os.close(write)
        return [_outcome(function, item) for item in items]
    if pid == 0:
        os.close(read)
        _child(function, items[1::2], write)
    os.close(write)
    with os.fdopen(read, "rb") as stream:
        finished = False
        try:
            mine = [reported(k, item, 2) for k, item in enumerate(items[0::2])]
            data = stream.read()
            _, status = os.waitpid(pid, 0)
            finished = True
        finally:
            if not finished:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
    theirs = pickle.loads(data) if status == 0 and data else None
    if not isinstance(theirs, list) or len(theirs) != len(items[1::2]):
        theirs = [_outcome(function, item) for item in items[1::2]]
    return [mine[k // 2] if k % 2 == 0 else theirs[k // 2] for k in range(len(items))]
