"""A cluster for one run: a local one started and stopped with it, or a running one joined
(:func:`open_cluster`).

A local cluster has one worker process per ``N`` of ``local:N``, each running one task at a
time (one burst; its torch threads are the job's, :mod:`lburst.cluster.models`), behind a
nanny that restarts a worker process that dies; the scheduler then runs the dead worker's
tasks again elsewhere, so a killed worker costs its task's time, not the run.
"""

from __future__ import annotations

import logging
import os
import socket
from contextlib import contextmanager
from typing import Any, Iterator

from lburst import memory as machine_memory
from lburst.cluster.spec import ClusterSpec
from lburst.errors import LBurstError, LBurstValueError
from lburst.extras import require
from lburst.memory import GIB
from lburst.process import environment_kept

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


#: resident memory of one local worker: the interpreter, torch, Dask, a network and one burst
#: (0.5 GB measured for lburst-b5 on a 5x640x480 burst)
WORKER_BYTES = GIB // 2


def usable_cores() -> int:
    """The CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def check_local_workers(workers: int) -> None:
    """``ValueError`` for a local cluster of more workers than this machine has cores, or than half
    of its memory holds (:data:`WORKER_BYTES` each): each worker runs one burst at a time on its own
    core, so more only share the cores and multiply the memory (local:64 on 2 cores did not finish)."""
    cores, limit = usable_cores(), machine_memory.memory_limit_bytes()
    fits = cores if limit is None else max(1, min(cores, limit // WORKER_BYTES))
    if workers > fits:
        memory = "" if limit is None else f", half its memory {limit / GIB:.1f} GiB"
        raise LBurstValueError(
            f"--cluster local:{workers}: a local worker runs one burst at a time on a core of its own (about "
            f"{WORKER_BYTES / GIB:.1f} GiB each), and this machine has {cores} cores{memory}: use local:{fits} or fewer"
        )


class ClusterError(LBurstError, RuntimeError):
    """The cluster failed the run: no scheduler at the address, a task that killed every
    worker that ran it, a lost connection; what finished is in the store."""


@contextmanager
def open_cluster(spec: ClusterSpec) -> Iterator[Any]:
    """A ``distributed.Client`` of the cluster of ``spec``, closed (and a local cluster
    stopped) when the block ends; a local cluster larger than the machine is refused first
    (:func:`check_local_workers`).  The environment variables that Dask sets in this process
    for the workers it spawns (``OMP_NUM_THREADS=1``, ``PYTHONHASHSEED``, ...) are taken back
    when the block ends."""
    with environment_kept():
        if spec.local:
            check_local_workers(spec.workers)
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
