"""The command line: --version, each group's own help, help text and defaults for every
option, one-line errors (no traceback) for bad input and operating-system errors,
the bf16 and CUDA checks, and clean-up of temporaries that a killed writer left."""

import errno
import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from lburst.burst.io import atomic_path, remove_stale_temporaries, save_burst
from lburst.cli import COMMANDS, build_parser, main
from lburst.model import network as model_module
from lburst.model import precision as precision_module

RUN_CLI = "import sys; from lburst.cli import main; sys.exit(main(sys.argv[1:]))"


def _cli(*args):
    return subprocess.run([sys.executable, "-c", RUN_CLI, *map(str, args)], capture_output=True, text=True, timeout=300)


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out.startswith("lburst 0.")


@pytest.mark.parametrize("group", ["simulate", "bench", "export"])
def test_a_group_without_its_subcommand_prints_its_own_help(group, capsys):
    assert main([group]) == 2
    out = capsys.readouterr().out
    assert out.startswith(f"usage: lburst {group}") and "SUBCOMMAND" in out


def test_every_option_of_every_command_has_help_and_shows_its_default():
    for words, _, _ in COMMANDS:
        parser = build_parser(words)
        sub = parser
        for word in words:
            sub = next(a for a in sub._actions if a.__class__.__name__ == "_SubParsersAction").choices[word]
        lacking = [a.dest for a in sub._actions if not a.help]
        assert not lacking, (words, lacking)
        text = sub.format_help()
        assert "(default: None)" not in text and "(default: False)" not in text
    assert (
        "(default: fp32)" in build_parser(("extract",))._subparsers._group_actions[0].choices["extract"].format_help()
    )


def test_simulate_flight_takes_out_as_an_option(tmp_path):
    assert (
        main(
            [
                "simulate",
                "flight",
                "--out",
                str(tmp_path / "scene"),
                "--bursts",
                "2",
                "--frames",
                "1",
                "--size",
                "64x48",
                "--supersample",
                "1",
            ]
        )
        == 0
    )
    assert (tmp_path / "scene" / "reference.json").is_file()
    # and a receiver's log of the same cameras, 2 m of noise by default, for --positions
    from lburst.sfm.positions import parse_positions
    from lburst.sfm.reference import Reference

    logged = parse_positions(tmp_path / "scene" / "positions.txt")
    truth = {name: -R.T @ t for name, (R, t) in Reference.load(tmp_path / "scene" / "reference.json").poses.items()}
    assert sorted(logged) == sorted(truth) == ["0000", "0001"]
    assert all(0 < abs(logged[n] - truth[n]).max() < 10 for n in truth)


def test_os_errors_are_one_line_naming_the_path(tmp_path):
    burst = tmp_path / "b0"
    save_burst(np.zeros((1, 32, 32, 3), np.uint8), burst)
    (tmp_path / "file").write_text("x")
    for out in (tmp_path / "file", tmp_path / "file" / "under"):
        proc = _cli("extract", burst, "--out", out, "--method", "sift")
        assert proc.returncode == 2 and "Traceback" not in proc.stderr
        last = proc.stderr.strip().splitlines()[-1]
        assert last.startswith("lburst extract: error: ") and f"{tmp_path / 'file'}" in last, proc.stderr
    run = tmp_path / "run"
    run.mkdir()
    (run / "last.pt").write_bytes(b"")
    proc = _cli("train", "--data", tmp_path, "--out", run, "--resume")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"lburst train: error: {run / 'last.pt'}: not a readable training state" in proc.stderr


def test_errors_have_one_format_and_the_documented_exit_codes(tmp_path, capsys, monkeypatch):
    from lburst.cli import methods as methods_command
    from lburst.errors import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, RunFailed

    # bad input: a missing photo (an lburst error) and a bad noise spec (a ValueError)
    assert main(["simulate", "burst", str(tmp_path / "none.png"), "--out", str(tmp_path / "b")]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("lburst simulate burst: error: ") and "none.png" in err[0], err
    assert main(["simulate", "burst", "--out", str(tmp_path / "b"), "--noise", "nope:1"]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("lburst simulate burst: error: ") and "nope:1" in err[0], err

    def failed(name=None):
        raise RunFailed("COLMAP registered no image")

    monkeypatch.setattr(methods_command, "listing", failed)
    assert main(["methods"]) == EXIT_FAILED
    assert capsys.readouterr().err == "lburst methods: error: COLMAP registered no image\n"

    def interrupted(name=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(methods_command, "listing", interrupted)
    assert main(["methods"]) == EXIT_INTERRUPTED
    assert capsys.readouterr().err.startswith("lburst methods: interrupted; ")


def test_the_exit_codes_are_documented_in_help_and_readme():
    from pathlib import Path

    from lburst.errors import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK

    text = build_parser().format_help()
    assert "exit status:" in text and '"lburst COMMAND: error: MESSAGE"' in text
    readme = (Path(__file__).parents[2] / "README.md").read_text()
    section = readme[readme.index("## Command line") :]
    section = section[: section.index("\n## ", 3)]
    assert "lburst COMMAND: error: MESSAGE" in section
    for code in (EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED):
        assert f"\n  {code} " in text and f"`{code}`" in section, code


def test_the_quick_start_commands_run_as_written_after_pip_install():
    from pathlib import Path

    readme = (Path(__file__).parents[2] / "README.md").read_text()
    start = readme.index("```bash", readme.index("Your own bursts"))
    lines = readme[start : readme.index("```", start + 3)].splitlines()[1:]
    assert lines and all(line.startswith("lburst ") for line in lines), lines  # no .venv to activate first


def test_a_bad_option_value_is_one_line(tmp_path):
    burst = tmp_path / "b0"
    save_burst(np.zeros((1, 32, 32, 3), np.uint8), burst)
    proc = _cli("extract", burst, "--out", tmp_path / "out", "--top-k", "-1")
    assert proc.returncode == 2 and proc.stderr.startswith("lburst extract: error: argument --top-k: ")
    assert proc.stderr.count("\n") == 1, proc.stderr  # no usage before it


@pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is here")
def test_device_cuda_without_cuda_is_one_clear_line(tmp_path):
    burst = tmp_path / "b0"
    save_burst(np.zeros((5, 32, 32, 3), np.uint8), burst)
    proc = _cli("extract", burst, "--out", tmp_path / "out", "--device", "cuda")
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert "CUDA is not available" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_bf16_on_a_cpu_without_native_bf16_warns(monkeypatch):
    monkeypatch.setattr(precision_module, "cpu_flags", lambda: {"sse2", "avx2"})
    with pytest.warns(RuntimeWarning, match="without native bf16"):
        model_module.check_precision("bf16", "cpu")
    monkeypatch.setattr(precision_module, "cpu_flags", lambda: {"avx2", "amx_bf16"})
    model_module.check_precision("bf16", "cpu")  # no warning: checked by -W error in pytest's filter below
    model_module.check_precision("fp32", "cpu")


pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


def test_a_full_disk_names_the_file_being_written(tmp_path, monkeypatch):
    def full(src, dst):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(OSError, match="No space left") as err:
        with atomic_path(tmp_path / "features.npz") as tmp:
            tmp.write_bytes(b"x")
    assert err.value.filename == str(tmp_path / "features.npz")
    assert [p.name for p in tmp_path.iterdir()] == []


def test_temporaries_of_a_killed_writer_are_removed_by_the_next_write(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".a.npz.{dead.pid}.x1y2.tmp.npz"
    live = tmp_path / f".a.npz.{os.getppid()}.z3.tmp.npz"  # a live process's write in progress
    stale.write_bytes(b"partial")
    live.write_bytes(b"partial")
    with atomic_path(tmp_path / "a.npz") as tmp:
        tmp.write_bytes(b"whole")
    assert not stale.exists() and live.exists() and (tmp_path / "a.npz").read_bytes() == b"whole"
    assert remove_stale_temporaries(tmp_path / "a.npz") == []


def _defaults(words: tuple[str, ...]) -> dict:
    sub = build_parser(words)
    for word in words:
        sub = next(a for a in sub._actions if a.__class__.__name__ == "_SubParsersAction").choices[word]
    return {a.dest: a.default for a in sub._actions if a.option_strings and a.dest != "help"}


# options that share a name but deliberately not a default, and why
OWN_DEFAULTS = {
    ("demo", "overlap"): "the demo's documented setting: sequential pairs, 4 next bursts (docs/defaults.md)",
    ("demo", "out"): "the demo has a report folder of its own, outputs/demo; the others ask for one",
}


def test_the_same_option_has_the_same_default_in_reconstruct_bench_and_demo(tmp_path):
    from lburst.bench.reconstruction import run_key

    reconstruct = _defaults(("reconstruct",))
    for words in (("bench", "reconstruction"), ("demo",)):
        for dest, default in _defaults(words).items():
            if dest in reconstruct and (words[0], dest) not in OWN_DEFAULTS:
                assert default == reconstruct[dest], (words, dest, default, reconstruct[dest])
    assert _defaults(("bench", "reconstruction"))["overlap"] is None  # automatic: 10 for a scene, 2 for a recording
    # a scene's finished runs from when bench's --overlap defaulted to 10 are the same run
    save_burst(np.zeros((1, 8, 8, 3), np.uint8), tmp_path / "scene" / "b0")
    assert run_key(tmp_path / "scene", {"overlap": None}) == run_key(tmp_path / "scene", {"overlap": 10})


@pytest.mark.parametrize(
    "argv, line",
    [
        (["extract", "b", "--out", "o", "--every", "0"], "lburst extract: error: argument --every: must be an integer"),
        (["reconstruct", "s", "--out", "o", "--matcher", "bogus"], "lburst reconstruct: error: argument --matcher: "),
        (["reconstruct", "s", "--out", "o", "--camera", "bogus"], "lburst reconstruct: error: argument --camera: "),
        (["extract", "b", "--out", "o", "--bogus"], "lburst extract: error: unrecognized arguments: --bogus"),
        (["extract"], "lburst extract: error: the following arguments are required"),
        (["simulate", "bogus"], "lburst simulate: error: argument SUBCOMMAND: invalid choice: 'bogus'"),
        (["bogus"], "lburst: error: argument COMMAND: invalid choice: 'bogus'"),
    ],
)
def test_a_usage_error_is_one_line_without_the_usage(argv, line, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(line) and err.count("\n") == 1, err


def test_the_exporter_says_nothing_of_the_torchvision_ops_it_skips(capfd):
    registration = pytest.importorskip("torch.onnx._internal.exporter._registration")
    if importlib.util.find_spec("torchvision") is not None:
        pytest.skip("torchvision is installed: torch's exporter has nothing to skip")
    from lburst.model.onnx import _quiet_exporter

    with _quiet_exporter():
        assert registration._get_overload("torchvision::nms") is None  # the call that warned
    assert capfd.readouterr().err == ""


@pytest.mark.slow
def test_export_onnx_prints_what_it_wrote_and_no_exporter_warnings(tmp_path):
    pytest.importorskip("onnxscript")
    from lburst.weights import weights_path

    proc = _cli("export", "onnx", weights_path("lburst-b5-lite"), "--out", tmp_path / "m.onnx")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "" and proc.stdout == f"wrote {tmp_path / 'm.onnx'}\n"  # no torchvision warnings
