"""A cluster for one run: a local one started and stopped with it, or a running one joined
(:func:`open_cluster`).

A local cluster has one worker process per ``N`` of ``local:N``, each running one task at a
time (one burst; its torch threads are the job's, :mod:`lburst.cluster.models`), behind a
nanny that restarts a worker process that dies; the scheduler then runs the dead worker's
tasks again elsewhere, so a killed worker costs its task's time, not the run.
"""

from __future__ import annotations

import logging
import socket
from contextlib import contextmanager
from typing import Any, Iterator

from lburst.cluster.spec import ClusterSpec
from lburst.errors import LBurstError
from lburst.extras import require

#: seconds to wait for a scheduler to answer (a remote cluster), or for a local cluster's workers
CONNECT_TIMEOUT_S = 60
#: seconds to wait for a TCP connection to a remote scheduler's port before the client starts: a
#: scheduler that is not there (connection refused, no route) is said at once, not after CONNECT_TIMEOUT_S
REACH_TIMEOUT_S = 5

#: Dask's environment for the worker processes it spawns, less ``MALLOC_TRIM_THRESHOLD_``:
#: Dask sets it (65536) to hand freed memory back to the system, which also fixes glibc's
#: mmap threshold, so that every large array of a burst is mapped afresh and its pages
#: faulted in again (on 20 bursts of 5x640x480: 27 s of system time against 4 s in one
#: process, docs/large_surveys.md).  A worker keeps one burst at a time, so its memory stays flat.
WORKER_ENVIRON = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


class ClusterError(LBurstError, RuntimeError):
    """The cluster failed the run: no scheduler at the address, a task that killed every
    worker that ran it, a lost connection; what finished is in the store."""


@contextmanager
def open_cluster(spec: ClusterSpec) -> Iterator[Any]:
    """A ``distributed.Client`` of the cluster of ``spec``, closed (and a local cluster
    stopped) when the block ends."""
    distributed = require("distributed", "--cluster")
    dask = require("dask", "--cluster")
    cluster = None
    try:
        if spec.local:
            with dask.config.set(WORKER_ENVIRON):
                cluster = distributed.LocalCluster(
                    n_workers=spec.workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=":0",  # a free port: another cluster on this machine may hold 8787
                    silence_logs=logging.CRITICAL,  # failures reach the client, which reports them
                )
            client = distributed.Client(cluster)
        else:
            check_reachable(spec)
            client = distributed.Client(spec.address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        if cluster is not None:
            cluster.close()
        raise ClusterError(f"--cluster {spec}: no cluster to run on ({exc})") from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def check_reachable(spec: ClusterSpec) -> None:
    """:class:`ClusterError` unless something accepts a TCP connection at the scheduler address of
    ``spec`` within :data:`REACH_TIMEOUT_S` (Dask's client would retry for :data:`CONNECT_TIMEOUT_S`)."""
    host, _, port = str(spec.address).split("://", 1)[1].rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=REACH_TIMEOUT_S).close()
    except OSError as exc:
        why = exc.strerror or str(exc) or type(exc).__name__
        raise ClusterError(f"--cluster {spec}: no scheduler answers there ({why})") from None


def worker_count(client: Any) -> int:
    """How many workers the cluster has now (at least 1, so that a cluster still starting gets work)."""
    return max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
