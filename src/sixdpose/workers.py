"""Worker processes of the local process pools (``register``'s images, ``generate``'s scenes).

Two rules, the same for every pool:

* a worker dies with its parent: :func:`init_worker` asks the kernel to send it ``SIGKILL`` when the
  parent dies (Linux ``prctl(PR_SET_PDEATHSIG)``) and, as a fallback (other systems, or a parent that
  died before the request), a daemon thread checks the parent's pid every ``poll_s`` seconds. Without
  this, a killed ``register --workers 2`` left its workers running for 10-20 s, writing BrokenPipe
  tracebacks into the dead parent's log;
* Ctrl-C belongs to the parent: a terminal sends ``SIGINT`` to the whole process group, workers
  included. Workers ignore it (:func:`init_worker`, and :func:`sigint_ignored` while the pool starts
  them, so that not even a worker still importing can print a ``KeyboardInterrupt`` traceback); the
  parent's ``KeyboardInterrupt`` leaves the pool's ``with`` block, which terminates the workers, and
  the command line prints one line (exit status 130).

:func:`process_pool` starts a pool under both rules and ends it: on success it closes the pool and waits
for its workers (``close`` + ``join``), on an exception or ``GeneratorExit`` it terminates them.
``Pool.terminate`` (what a pool's own ``with`` block calls, also on success) first takes the task
queue's read lock, which an idle worker holds while it waits for a task: a worker killed while it waits
leaves that lock taken and ``terminate`` waits for ever.

``PR_SET_PDEATHSIG`` fires when the *thread* that started the worker ends, not the process. A pool with
``maxtasksperchild`` starts the replacement workers from its own handler thread, which ends when the
pool is terminated: those workers were killed while idle, and ``generate --workers 1`` (60 scenes, a
worker replaced after 50) hung at the end with every scene written. :func:`process_pool` therefore sets
each worker up with the kernel's signal only for pools that never replace a worker; the others rely on
the watcher thread (within ``poll_s``).
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time

_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _parent_pid() -> int:
    """The pid of the process that started this one (the pool's owner, for a multiprocessing worker)."""
    parent = multiprocessing.parent_process()
    return parent.pid if parent is not None and parent.pid is not None else os.getppid()


def _watch_parent(parent: int, poll_s: float) -> None:
    while True:
        if os.getppid() != parent:
            os._exit(1)  # the parent is gone: no cleanup, no traceback, nothing left running
        time.sleep(poll_s)


def init_worker(poll_s: float = 1.0, deathsig: bool = True) -> None:
    """Set up the calling worker process: ignore ``SIGINT`` and die with the parent.

    Call it first in a pool initializer. With ``deathsig`` on Linux the kernel kills the worker the
    moment the parent thread that started it ends (``PR_SET_PDEATHSIG`` = ``SIGKILL``: pass False where a
    pool's handler thread may start workers, see the module's docstring); everywhere, a daemon thread
    exits the worker within ``poll_s`` seconds (float) of the parent's death, and a worker whose parent is
    already gone exits now.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = _parent_pid()
    if deathsig and sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the watcher thread alone
            pass
    if os.getppid() != parent:
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent, poll_s), name="sixdpose-parent-watch", daemon=True).start()


@contextlib.contextmanager
def sigint_ignored():
    """Ignore ``SIGINT`` in this process while the block runs (wrap the creation of a spawn pool).

    Processes started meanwhile inherit the ignored signal through ``exec`` and Python keeps it
    ignored at start-up, so a Ctrl-C cannot interrupt a worker before :func:`init_worker` runs. Does
    nothing outside the main thread (only it may set signal handlers).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old if old is not None else signal.SIG_DFL)  # None: set outside Python


def _start_worker(deathsig: bool, initializer, *initargs) -> None:
    init_worker(deathsig=deathsig)
    initializer(*initargs)


@contextlib.contextmanager
def process_pool(workers: int, initializer, initargs: tuple = (), maxtasksperchild: int | None = None):
    """A ``spawn`` process pool of ``workers`` processes for the ``with`` block, started with Ctrl-C ignored.

    Each worker runs :func:`init_worker` (with the kernel's death signal only when ``maxtasksperchild``
    is None: see the module's docstring), then ``initializer(*initargs)``. Leaving the block normally closes
    the pool and waits for its workers; leaving it by an exception (``KeyboardInterrupt`` and a closed
    generator's ``GeneratorExit`` included) terminates them and re-raises.
    """
    ctx = multiprocessing.get_context("spawn")
    with sigint_ignored():  # the workers start with Ctrl-C ignored: the parent alone handles it
        pool = ctx.Pool(workers, initializer=_start_worker,
                        initargs=(maxtasksperchild is None, initializer, *initargs), maxtasksperchild=maxtasksperchild)
    try:
        yield pool
    except BaseException:
        pool.terminate()
        raise
    pool.close()
    pool.join()
