"""How a reconstruction's cost grows with the number of keyframes: long simulated loop flights
(``lburst simulate flight --loop --bursts N``), each reconstructed with each mapper.

For each N: the scene is simulated once (``ROOT/scenes/loopN``); its features are computed
once by the features stage of ``lburst reconstruct`` (``ROOT/runs/loopN/features``:
:meth:`lburst.sfm.inputs.SceneInput.read`) and timed as *decode* (reading the bursts)
and *features* (the rest: the network, alignment, writing the store and the images); then
``lburst reconstruct`` runs once per mapper on the stored features (``--features``), timed by
stage: *pairs* (the pair plan, retrieval's VLAD vectors and candidates), *matches*, and
*COLMAP* (the child process: database, geometric verification, mapping with bundle
adjustment, export).  Each stage's peak memory is the resident high-water mark of its
process during the stage (reset before it, ``/proc/self/clear_refs``), COLMAP's that of its
child.  Also: registered keyframes, ATE (m and % of the path) against ``reference.json``.

Every step runs in its own child process, and the results go to ``ROOT/scaling.json`` as
they come: a rerun reuses the simulated scenes, the stored features (and their first
timing) and every finished (N, mapper) row, and computes only what is missing.

    python scripts/survey_scaling.py --root outputs/survey_scaling --sizes 100 300 --threads 1
    python scripts/survey_scaling.py --root outputs/survey_scaling --sizes 1000 --threads 1   # hours
    python scripts/survey_scaling.py --sizes 300 --mappers incremental+gnss   # with GNSS priors
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

MAPPERS = ("incremental", "global")
#: the incremental mapper with the scene's GNSS positions as priors (``lburst reconstruct --positions``)
WITH_GNSS = "incremental+gnss"


def reset_peak() -> None:
    """Reset this process's resident high-water mark (VmHWM), Linux 4.0+."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def peak_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class Stage:
    """Seconds and peak memory (MiB) of the calls it wraps, summed and maxed over calls."""

    def __init__(self) -> None:
        self.seconds, self.peak = 0.0, 0.0

    def wrap(self, function):
        def timed(*args, **kwargs):
            reset_peak()
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start
                self.peak = max(self.peak, peak_mib())

        return timed

    def row(self) -> dict:
        return {"s": round(self.seconds, 2), "peak_mib": round(self.peak, 1)}


def child_features(args: argparse.Namespace) -> dict:
    """The features stage of scene ``args.n`` (decode timed apart)."""
    import torch

    import lburst.sfm.feature_stage as stage_module
    from lburst.sfm import inputs
    from lburst.sfm.options import ReconstructOptions

    torch.set_num_threads(args.threads)
    decode = Stage()
    inputs.load_item = decode.wrap(inputs.load_item)
    calls = []
    original = stage_module.compute_burst

    def counted(job):
        calls.append(job.burst.name)
        return original(job)

    stage_module.compute_burst = counted
    total = Stage()
    source = inputs.SceneInput(scene_dir(args, args.n))
    total.wrap(source.read)(args.method, run_dir(args, args.n) / "features", ReconstructOptions(progress=False))
    return {
        "computed": len(calls),
        "decode": decode.row(),
        "features": {"s": round(total.seconds - decode.seconds, 2), "peak_mib": round(total.peak, 1)},
    }


def child_reconstruct(args: argparse.Namespace) -> dict:
    """``lburst reconstruct`` of scene ``args.n`` with ``args.mapper`` on the stored features, by stage."""
    import torch

    import lburst.sfm.mapping as mapping
    import lburst.sfm.read as read
    import lburst.sfm.reconstruct as rec
    from lburst.sfm.options import ReconstructOptions

    torch.set_num_threads(args.threads)
    pairs, matches, colmap = Stage(), Stage(), Stage()
    read.pair_plan, read.make_pairs = pairs.wrap(read.pair_plan), pairs.wrap(read.make_pairs)  # as the stages call them
    rec.vlad, rec.retrieval_pairs = pairs.wrap(rec.vlad), pairs.wrap(rec.retrieval_pairs)
    rec.match_or_reuse = matches.wrap(rec.match_or_reuse)
    lines: list[str] = []
    run_job = mapping.run_job_subprocess
    mapping.run_job_subprocess = colmap.wrap(lambda job_dir, report=None: run_job(job_dir, report=lines.append))
    gnss = args.mapper == WITH_GNSS
    options = ReconstructOptions(
        mapper="incremental" if gnss else args.mapper,
        positions=positions_file(args, args.n) if gnss else None,
        num_threads=args.threads,
        progress=False,
        retrieval=args.retrieval,
        near=args.near,
        features=run_dir(args, args.n) / "features" / "features",
    )
    out = run_dir(args, args.n) / args.mapper
    start = time.perf_counter()
    result = rec.reconstruct_scene(scene_dir(args, args.n), args.method, out, options)
    total = time.perf_counter() - start
    colmap_row = colmap.row()
    colmap_row["peak_mib"] = round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, 1)
    colmap_row["stages"] = [line for line in lines if line.rstrip().endswith(" s")]
    m = result.metrics
    return {
        "pairs": {**pairs.row(), "count": m.get("pairs"), "loop_candidates": m.get("loop_candidates")},
        "matches": matches.row(),
        "colmap": colmap_row,
        "reconstruct_s": round(total, 1),
        "status": str(result.status),
        "registered": len(result.registered),
        "keyframes": len(result.names),
        "ate_m": m.get("ate_rmse"),
        "ate_pct": m.get("ate_percent"),
    }


def spacing(args: argparse.Namespace, n: int) -> float | None:
    """Metres between bursts: ``--loop-length / (N - 1)`` for N above ``--dense-from``, else simulate's own."""
    return round(args.loop_length / (n - 1), 4) if args.loop_length and n >= args.dense_from else None


def scene_name(args: argparse.Namespace, n: int) -> str:
    """The key of scene N in scaling.json: ``N``, or ``N@LENGTHm`` along a loop of ``--loop-length``."""
    return f"{n}" if spacing(args, n) is None else f"{n}@{args.loop_length:g}m"


def scene_dir(args: argparse.Namespace, n: int) -> Path:
    return args.root / "scenes" / f"loop{scene_name(args, n).replace('@', '_')}"


def run_dir(args: argparse.Namespace, n: int) -> Path:
    return args.root / "runs" / f"loop{scene_name(args, n).replace('@', '_')}"


def run_child(args: argparse.Namespace, *extra: str) -> dict:
    cmd = [sys.executable, __file__, "--root", str(args.root), "--method", args.method, "--threads", str(args.threads)]
    cmd += ["--retrieval", str(args.retrieval)] if args.retrieval is not None else []
    cmd += ["--near", str(args.near)] if args.near is not None else []
    cmd += ["--loop-length", str(args.loop_length), "--dense-from", str(args.dense_from)] if args.loop_length else []
    cmd += ["--gnss-noise", str(args.gnss_noise)]
    done = subprocess.run([*cmd, *extra], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(extra)} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def simulate(args: argparse.Namespace, n: int) -> dict | None:
    scene = scene_dir(args, n)
    if (scene / "reference.json").is_file() and len([p for p in scene.iterdir() if p.is_dir()]) == n:
        return None
    start = time.perf_counter()
    cmd = ["lburst", "simulate", "flight", str(scene), "--loop", "--bursts", str(n), "--size", args.size]
    cmd += ["--spacing", str(spacing(args, n))] if spacing(args, n) is not None else []
    subprocess.run(cmd, check=True, capture_output=True)
    return {"s": round(time.perf_counter() - start, 1)}


def positions_file(args: argparse.Namespace, n: int) -> Path:
    """Scene N's ``positions.txt`` (what ``lburst simulate flight`` writes: the true centres plus
    ``--gnss-noise`` m of seeded noise), written from its config if the scene predates it."""
    from lburst.scenes.night_flight import NightFlightConfig, gnss_positions
    from lburst.sfm.positions import POSITIONS_FILE, write_positions

    path = scene_dir(args, n) / POSITIONS_FILE
    if not path.is_file():
        cfg = NightFlightConfig.from_dict(json.loads((scene_dir(args, n) / "night_flight.json").read_text()))
        write_positions(path, gnss_positions(cfg, args.gnss_noise))
    return path


def save(args: argparse.Namespace, data: dict) -> None:
    """``ROOT/scaling.json``, atomically, merged with what another run of this script (other
    sizes) saved meanwhile."""
    path = args.root / "scaling.json"
    if path.is_file():
        for section, rows in json.loads(path.read_text()).items():
            if isinstance(rows, dict):
                data[section] = {**rows, **data.get(section, {})}
    tmp = path.with_suffix(f".json.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=1))
    os.replace(tmp, path)


def colmap_seconds(row: dict, stage: str) -> str:
    """Seconds of the COLMAP stage whose line starts with ``COLMAP <stage>`` (summed), or ``-``."""
    found = [
        float(line.rsplit(": ", 1)[1].split()[0])
        for line in row["colmap"]["stages"]
        if line.startswith(f"COLMAP {stage}")
    ]
    return f"{sum(found):.1f}" if found else "-"


def table(data: dict) -> str:
    head = (
        "| keyframes | mapper | decode (s) | features (s) | pairs (s) | pairs | matches (s) | COLMAP (s) "
        "| of which verification / mapping (s) | peak MiB features / matches / COLMAP | registered | ATE (m) | ATE % |"
    )
    lines = [head, "|" + "---:|" * 2 + "---:|" * 11]
    for key in sorted(data["runs"], key=lambda k: (int(k.split("/")[0].split("@")[0]), k)):
        n, mapper = key.split("/")
        r, f = data["runs"][key], data["features"].get(n, {})
        computed = f.get("computed")
        share = f" ({computed} computed)" if computed is not None and computed < int(n.split("@")[0]) else ""
        n = n.replace("@", " on a loop of ")
        ate = "-" if r["ate_m"] is None else f"{r['ate_m']:.3g}"
        pct = "-" if r["ate_pct"] is None else f"{r['ate_pct']:.2f}"
        lines.append(
            f"| {n} | {mapper} | {f.get('decode', {}).get('s', '-')} | {f.get('features', {}).get('s', '-')}{share} "
            f"| {r['pairs']['s']} | {r['pairs']['count']} | {r['matches']['s']} | {r['colmap']['s']} "
            f"| {colmap_seconds(r, 'geometric verification')} / {colmap_seconds(r, 'mapping')} "
            f"| {f.get('features', {}).get('peak_mib', '-')} / {r['matches']['peak_mib']} / {r['colmap']['peak_mib']} "
            f"| {r['registered']}/{r['keyframes']} | {ate} | {pct} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", type=Path, default=Path("outputs/survey_scaling"))
    parser.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000])
    parser.add_argument(
        "--mappers",
        nargs="+",
        choices=[*MAPPERS, WITH_GNSS],
        default=list(MAPPERS),
        help=f"{WITH_GNSS}: the incremental mapper with the scene's positions.txt as priors",
    )
    parser.add_argument("--gnss-noise", type=float, default=2.0, help="metres of noise of a scene's positions.txt")
    parser.add_argument("--size", default="320x240", help="image size of the simulated flight")
    parser.add_argument("--method", default="lburst")
    parser.add_argument("--threads", type=int, default=1, help="torch and COLMAP threads")
    parser.add_argument("--retrieval", type=int, help="lburst reconstruct --retrieval (default: its own)")
    parser.add_argument("--near", type=int, help="lburst reconstruct --near (default: its own)")
    parser.add_argument(
        "--loop-length",
        type=float,
        help="fly N >= --dense-from bursts along a loop of this length (metres) instead of 8 m apart: the "
        "simulated world grows with the path, and 1000 bursts 8 m apart need over 20 GB",
    )
    parser.add_argument("--dense-from", type=int, default=1000)
    parser.add_argument("--child", nargs="+", help=argparse.SUPPRESS)  # features N | reconstruct N MAPPER
    args = parser.parse_args()
    if args.child:
        args.n = int(args.child[1])
        args.mapper = args.child[2] if len(args.child) > 2 else None
        print(json.dumps(child_features(args) if args.child[0] == "features" else child_reconstruct(args)))
        return
    from lburst.model.precision import cpu_name

    path = args.root / "scaling.json"
    data = json.loads(path.read_text()) if path.is_file() else {"features": {}, "runs": {}, "simulate": {}}
    data.update(cpu=cpu_name(), size=args.size, method=args.method, threads=args.threads)
    for n in args.sizes:
        if (sim := simulate(args, n)) is not None:
            data["simulate"][scene_name(args, n)] = sim
        features = run_child(args, "--child", "features", str(n))
        name = scene_name(args, n)
        if features["computed"] or name not in data["features"]:
            data["features"][name] = features  # else keep the timing of the run that computed them
        save(args, data)
        for mapper in args.mappers:
            if f"{name}/{mapper}" in data["runs"]:
                continue
            data["runs"][f"{name}/{mapper}"] = run_child(args, "--child", "reconstruct", str(n), mapper)
            save(args, data)
            print(table(data), flush=True)
    print(table(data))
    (args.root / "scaling.md").write_text(table(json.loads(path.read_text())) + "\n")


if __name__ == "__main__":
    main()
