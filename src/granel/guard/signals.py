"""Stops from outside: SIGTERM raises `Terminated` in the main thread (as Ctrl-C raises
KeyboardInterrupt), so that every `finally` and every atomic write cleans up on the way out;
dask workers ignore the terminal's Ctrl-C (their parent stops them) and keep their logs quiet."""

from __future__ import annotations

import logging
import signal
import threading
from contextlib import contextmanager

from .exits import Terminated


def _raise_terminated(signum, frame):
    raise Terminated()


@contextmanager
def stops_as_exceptions():
    """SIGTERM -> Terminated and SIGINT -> KeyboardInterrupt while the block runs (main thread
    only; elsewhere, nothing changes), the earlier handlers restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old_term = signal.signal(signal.SIGTERM, _raise_terminated)
    old_int = signal.getsignal(signal.SIGINT)
    if old_int in (signal.SIG_DFL, None):
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old_term)
        if old_int in (signal.SIG_DFL, None):
            signal.signal(signal.SIGINT, old_int or signal.SIG_DFL)


QUIET_LOGGERS = ("distributed", "tornado", "asyncio", "bokeh")


def quiet_dask() -> None:
    """dask.distributed's own logging down to its critical messages: a study reports its cases'
    failures itself, and a stop (Ctrl-C, SIGTERM, a worker killed) must not print pages."""
    for name in QUIET_LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)
    try:
        import dask

        dask.config.set({"distributed.logging.distributed": "critical", "distributed.admin.log-length": 0})
    except ImportError:  # pragma: no cover - dask is a dependency
        pass


def worker_setup() -> None:
    """Run in every dask worker process at start (a preload): the terminal's Ctrl-C reaches the
    whole process group, but a worker is stopped by its parent, so it ignores SIGINT; its logs are
    quiet as its parent's."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    quiet_dask()


def dask_setup(worker=None):  # dask's preload hook: `distributed.worker.preload` names this module
    worker_setup()


MAX_WORKERS = 1024  # local worker processes a study may start


def check_workers(workers: int) -> None:
    """InputError unless `workers` is a whole number of local worker processes from 1 to MAX_WORKERS."""
    from .exits import InputError

    if not 1 <= workers <= MAX_WORKERS:
        raise InputError(f"--workers {workers}: give a whole number of worker processes from 1 to {MAX_WORKERS}")


def local_cluster(workers: int):
    """A LocalCluster of `workers` single-thread processes whose workers run `worker_setup`
    (ignore the terminal's Ctrl-C, quiet logs), with the parent's dask logging quiet too."""
    from dask.distributed import LocalCluster

    quiet_dask()
    return LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=None,
                        preload=["granel.guard.signals"], silence_logs=logging.CRITICAL)


def pool_initializer() -> None:
    """A process pool's initializer (movies, the paper's reference run): as `worker_setup`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
