"""Where many solves run: in this process, on a Dask LocalCluster of single-threaded worker
processes, or on a running Dask scheduler (``tcp://host:port``). The same code serves a laptop
and a cluster; CasADi Functions are never sent between processes (each worker builds its own).
"""

from __future__ import annotations

import contextlib
import logging
import os

LOCAL, SERIAL = "local", "none"


def check_address(scheduler: str, name: str = "--scheduler", extra: tuple = ()) -> str:
    """``local``, ``none`` (and ``extra`` words) or a scheduler address (``tcp://host:port`` or
    ``host:port``); anything else is a one-line error naming ``name``."""
    if scheduler in (LOCAL, SERIAL) + tuple(extra):
        return scheduler
    address = str(scheduler).split("://", 1)[-1]
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        words = ", ".join(repr(w) for w in tuple(extra) + (LOCAL, SERIAL))
        raise ValueError(f"{name}: expected {words} or an address like tcp://127.0.0.1:8786, got {scheduler!r}")
    return scheduler


@contextlib.contextmanager
def dask_client(scheduler: str, n_workers: int | None = None, max_workers: int | None = None):
    """A ``distributed.Client`` on a LocalCluster (``local``: ``n_workers`` single-threaded
    processes, default the CPUs, at most ``max_workers``) or on the scheduler at that address;
    the LocalCluster is closed on exit."""
    from distributed import Client, LocalCluster

    cluster = None
    if scheduler == LOCAL:
        n = max(1, min(n_workers or os.cpu_count() or 1, max_workers or 10 ** 6))
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
    try:
        with Client(cluster if cluster is not None else scheduler, timeout="15s") as client:
            yield client
    finally:
        if cluster is not None:
            cluster.close()
