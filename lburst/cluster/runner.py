"""One call that maps a per-burst function over jobs, in this process or on a cluster:
:meth:`Runner.map` yields ``(job, result)`` pairs where ``result()`` returns what the function
returned for the job, or raises what it raised, so that the caller handles a failed burst as
it would in a plain loop.  Both show a tqdm bar over finished jobs, from :data:`BAR_DELAY_S`
on, so that a map that ends at once (nothing to do, or an input error) prints nothing.

On a cluster (:class:`ClusterRunner`) jobs are submitted as the caller's iterator gives them,
at most a few per worker ahead (:data:`AHEAD_PER_WORKER`), so a stream of keyframe bursts
decoded here never piles up; results come in the order tasks finish.  An error of the
iterator itself (a recording that stops) ends the map after the jobs already submitted have
finished, then is raised.  A task whose workers died :data:`distributed.scheduler.allowed-failures`
times raises :class:`lburst.cluster.session.ClusterError`.
"""

from __future__ import annotations

from contextlib import contextmanager
from functools import partial
from typing import Any, Callable, Iterable, Iterator

from tqdm import tqdm

from lburst.cluster.session import ClusterError, open_cluster, worker_count
from lburst.cluster.spec import ClusterSpec

#: tasks in flight per worker: one running, the next ones already shipped
AHEAD_PER_WORKER = 2
#: seconds before a map's bar appears (tqdm's ``delay``)
BAR_DELAY_S = 1.0


class Runner:
    """Runs jobs in this process, one after another."""

    #: torch threads of a job when the caller sets none (``None``: this process's own)
    threads: int | None = None
    workers = 1
    #: jobs run in other processes (worth batching small ones)
    remote = False

    def map(
        self, function: Callable, jobs: Iterable, desc: str, progress: bool = True, total: int | None = None, **bar
    ) -> Iterator[tuple[Any, Callable[[], Any]]]:
        for job in tqdm(jobs, desc=desc, total=total, disable=not progress, leave=False, delay=BAR_DELAY_S, **bar):
            yield job, partial(function, job)

    def share(self, values: list) -> list:
        """``values`` as jobs can hold them (on a cluster: sent to the workers once)."""
        return values


class ClusterRunner(Runner):
    """Runs jobs as tasks on the cluster of a ``distributed.Client``, one torch thread each by default."""

    threads = 1
    remote = True

    def __init__(self, client: Any) -> None:
        self.client = client

    @property
    def workers(self) -> int:
        return worker_count(self.client)

    def share(self, values: list) -> list:
        return self.client.scatter(values)

    def map(
        self, function: Callable, jobs: Iterable, desc: str, progress: bool = True, total: int | None = None, **bar
    ) -> Iterator[tuple[Any, Callable[[], Any]]]:
        from distributed import as_completed

        source = iter(jobs)
        pending: dict[Any, Any] = {}
        done = as_completed()
        stopped: list[BaseException] = []
        ahead = AHEAD_PER_WORKER * self.workers

        def submit() -> None:
            while not stopped and len(pending) < ahead:
                try:
                    job = next(source)
                except StopIteration:
                    return
                except Exception as exc:  # the jobs' own source failed: finish what was sent, then raise
                    stopped.append(exc)
                    return
                future = self.client.submit(_capture, function, job, pure=False)
                pending[future] = job
                done.add(future)

        submit()
        with tqdm(desc=desc, total=total, disable=not progress, leave=False, delay=BAR_DELAY_S, **bar) as counter:
            while pending:
                future = next(done)
                job = pending.pop(future)
                counter.update()
                yield job, partial(_result, future, job)
                submit()
        if stopped:
            raise stopped[0]


def _capture(function: Callable, job: Any) -> tuple[bool, Any]:
    """``(True, function(job))``, or ``(False, the exception it raised)``: a job's own failure
    comes back as a value, so the engine neither logs it on the worker nor counts it as its own."""
    try:
        return True, function(job)
    except Exception as exc:
        return False, exc


def _result(future: Any, job: Any) -> Any:
    from distributed import KilledWorker
    from distributed.comm.core import CommClosedError

    try:
        ok, value = future.result()
    except (KilledWorker, CommClosedError) as exc:
        raise ClusterError(f"{getattr(job, 'name', job)}: {type(exc).__name__}: {exc}") from None
    if not ok:
        raise value
    return value


@contextmanager
def open_runner(spec: ClusterSpec | None) -> Iterator[Runner]:
    """A :class:`Runner` of this process (``spec`` ``None``), or a :class:`ClusterRunner` of the cluster of ``spec``."""
    if spec is None:
        yield Runner()
        return
    with open_cluster(spec) as client:
        yield ClusterRunner(client)
