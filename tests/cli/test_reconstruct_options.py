"""``lburst reconstruct`` and ``lburst bench reconstruction`` share one table of reconstruction
options (:mod:`lburst.cli.reconstruct_options`): each flag sets one ``ReconstructOptions`` field,
both commands read it alike, and a benchmark run keeps the key of runs stored before the table."""

from __future__ import annotations

from dataclasses import fields

from lburst.cli import build_parser
from lburst.cli.reconstruct_options import BENCH_KEYED, BENCH_OPTIONS, RECONSTRUCT_OPTIONS, bench_options
from lburst.sfm.options import ReconstructOptions

FLAGS = [
    "--pairs", "sequential", "--overlap", "3", "--near", "1", "--mapper", "global", "--camera", "reference",
    "--fix-intrinsics", "--camera-per-image", "--threads", "1", "--matcher", "ratio", "--retrieval", "4",
    "--loop-fraction", "0.5", "--abs-pose-inliers", "12", "--mapper-threads", "1", "--camera-model", "PINHOLE",
]  # fmt: skip


def _parse(argv: list[str]):
    return build_parser(tuple(argv[: 2 if argv[0] == "bench" else 1])).parse_args(argv)


def test_each_option_sets_a_field_of_reconstruct_options():
    names = {f.name for f in fields(ReconstructOptions)}
    assert {o.name for o in RECONSTRUCT_OPTIONS if o.name is not None} <= names
    assert {o.flag for o in BENCH_OPTIONS} >= {
        "--pairs", "--overlap", "--fallback-exhaustive", "--mapper", "--camera", "--fix-intrinsics",
        "--single-camera", "--threads", "--matcher",
    }  # fmt: skip


def test_reconstruct_and_bench_read_the_same_flags_into_the_same_options():
    from lburst.cli.reconstruct_options import reconstruct_options

    run = reconstruct_options(_parse(["reconstruct", "scene", "--out", "o", *FLAGS]))
    bench = bench_options(_parse(["bench", "reconstruction", "scene", "--out", "o", *FLAGS]))
    assert bench == {k: v for k, v in run.items() if k in bench}
    assert bench["single_camera"] is False and bench["num_threads"] == 1 and bench["near"] == 1
    assert set(run) - {o.name for o in BENCH_OPTIONS} == {"seed", "positions", "input_positions", "position_std"}
    ReconstructOptions(**run)  # every value is one ReconstructOptions takes


def test_a_benchmark_run_keeps_the_key_of_runs_stored_before():
    plain = bench_options(_parse(["bench", "reconstruction", "scene", "--out", "o"]))
    assert set(plain) == set(BENCH_KEYED)  # what every run's key held before the options were shared
    assert plain["single_camera"] is None and plain["num_threads"] == 2 and plain["mapper"] == "incremental"
    fixed = bench_options(_parse(["bench", "reconstruction", "scene", "--out", "o", "--fix-intrinsics", "--near", "3"]))
    assert set(fixed) - set(plain) == {"fix_intrinsics", "near"}
