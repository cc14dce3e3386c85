"""Dask's ``distributed`` against Ray on this machine: what a local cluster of 2 worker
processes costs before any work, and what one burst task costs beyond its work.

For each engine, in its own process: the seconds from nothing to a cluster of 2 worker
processes ready for tasks (``start_s``); the memory of that idle cluster, the sum of the
proportional set sizes (PSS, shared pages split among the processes that share them) of the
driver and every process it started, less the driver's own before the start
(``idle_mib``); the round-trip seconds of a task that does nothing (``noop_ms``, median of
``--repeats`` submitted one after another, and ``noop_batch_ms``: a batch of ``--batch``
tasks submitted at once, per task); and the round trip of a task that receives a burst
``5 x 480 x 640 x 3`` uint8 (4.6 MB) and returns a features dict of 4000 keypoints with
128-D float32 descriptors (2.1 MB), doing nothing else (``burst_ms``).  Those are the
engine's overhead per burst, to set beside seconds of extraction per burst.

    python scripts/cluster_engines.py --out outputs/cluster_engines.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

ENGINES = ("dask", "ray")


def noop(x=None):
    return None


def fake_extract(burst):
    """What a burst task returns: a features dict of 4000 keypoints (its content does not matter)."""
    import numpy as np

    k = 4000
    return {
        "keypoints": np.zeros((k, 2), np.float32) + burst.shape[0],
        "scales": np.ones(k, np.float32),
        "scores": np.ones(k, np.float32),
        "descriptors": np.ones((k, 128), np.float32),
    }


def tree_pss_mib() -> float:
    """PSS (MiB) of this process and all its descendants."""
    import psutil

    me = psutil.Process()
    total = 0
    for p in [me, *me.children(recursive=True)]:
        try:
            total += p.memory_full_info().pss
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            pass
    return total / 2**20


def timed(submit_and_wait, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        submit_and_wait()
        times.append(time.perf_counter() - start)
    return statistics.median(times) * 1000


def measure(engine: str, repeats: int, batch: int) -> dict:
    import numpy as np

    burst = np.random.default_rng(0).integers(0, 255, (5, 480, 640, 3), dtype=np.uint8)
    before = tree_pss_mib()
    start = time.perf_counter()
    if engine == "dask":
        from dask.distributed import Client, LocalCluster

        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
        client.wait_for_workers(2)
        start_s = time.perf_counter() - start
        client.submit(noop, pure=False).result()  # first task: the function is shipped once
        time.sleep(2)
        idle = tree_pss_mib() - before
        noop_ms = timed(lambda: client.submit(noop, pure=False).result(), repeats)
        t0 = time.perf_counter()
        client.gather(client.map(noop, range(batch), pure=False))
        noop_batch_ms = (time.perf_counter() - t0) / batch * 1000
        burst_ms = timed(lambda: client.submit(fake_extract, burst, pure=False).result(), repeats)
        client.close()
        cluster.close()
    else:
        import ray

        ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR", log_to_driver=False)
        remote_noop = ray.remote(num_cpus=1)(noop)
        remote_extract = ray.remote(num_cpus=1)(fake_extract)
        # Ray starts workers lazily; ready means two worker processes have run a task
        ray.get([remote_noop.remote(i) for i in range(2)])
        start_s = time.perf_counter() - start
        time.sleep(2)
        idle = tree_pss_mib() - before
        noop_ms = timed(lambda: ray.get(remote_noop.remote()), repeats)
        t0 = time.perf_counter()
        ray.get([remote_noop.remote(i) for i in range(batch)])
        noop_batch_ms = (time.perf_counter() - t0) / batch * 1000
        burst_ms = timed(lambda: ray.get(remote_extract.remote(burst)), repeats)
        ray.shutdown()
    return {
        "engine": engine,
        "start_s": round(start_s, 2),
        "idle_mib": round(idle, 1),
        "noop_ms": round(noop_ms, 2),
        "noop_batch_ms": round(noop_batch_ms, 2),
        "burst_ms": round(burst_ms, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--engines", nargs="+", choices=ENGINES, default=list(ENGINES))
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--batch", type=int, default=200)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--one", choices=ENGINES, help=argparse.SUPPRESS)  # child process: one engine
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(args.one, args.repeats, args.batch)))
        return
    rows = []
    for engine in args.engines:
        cmd = [sys.executable, __file__, "--one", engine, "--repeats", str(args.repeats), "--batch", str(args.batch)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=True)
        rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
    from lburst.model.precision import cpu_name

    print(f"CPU: {cpu_name()}")
    print(
        "| engine | start (s) | idle 2 workers (MiB PSS) | no-op task (ms) | no-op, 200 at once (ms/task) | burst task (ms) |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['engine']} | {r['start_s']} | {r['idle_mib']} | {r['noop_ms']} | {r['noop_batch_ms']} | {r['burst_ms']} |"
        )
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"cpu": cpu_name(), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
