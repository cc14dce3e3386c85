"""The ``lburst`` command line, and all of it: every subcommand lives in one module of
this package (``lburst/cli/<command>.py``), which defines ``configure_parser(parser)``
(its options) and ``main(args) -> int`` (its exit code); options that several commands
share are in :mod:`lburst.cli.options`.  This file only wires them up, importing a
module when its subcommand runs.  No module outside this package parses arguments."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings
from typing import NoReturn

import lburst
from lburst.errors import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, LBurstError, LBurstValueError
from lburst.process import state_kept

# (subcommand words, module, one-line help)
COMMANDS: list[tuple[tuple[str, ...], str, str]] = [
    (("extract",), "lburst.cli.extract", "features of bursts to .npz (and hloc features.h5)"),
    (("show",), "lburst.cli.show", "picture of a burst's keypoints and confidence maps"),
    (("methods",), "lburst.cli.methods", "feature methods and matchers, with their options and defaults"),
    (("simulate", "burst"), "lburst.cli.simulate_burst", "a low-light burst from one photo"),
    (("simulate", "scene"), "lburst.cli.simulate_scene", "a low-light burst scene from a multi-view photo set"),
    (("simulate", "sequences"), "lburst.cli.simulate_sequences", "HPatches-style homography sequences from photos"),
    (("simulate", "flight"), "lburst.cli.simulate_flight", "the synthetic night flight scene with exact ground truth"),
    (("train",), "lburst.cli.train", "self-supervised training of a burst (or single-image) network"),
    (("bench", "homography"), "lburst.cli.bench_homography", "noisy-burst homography benchmark (MMA, repeatability)"),
    (("bench", "reconstruction"), "lburst.cli.bench_reconstruction", "reconstruction benchmark on burst scenes"),
    (("reconstruct",), "lburst.cli.reconstruct", "a 3D model of a burst scene with COLMAP"),
    (("demo",), "lburst.cli.demo", "synthetic night flight: LBurst vs SIFT, with a report"),
    (("export", "onnx"), "lburst.cli.export_onnx", "export a network to ONNX"),
    (("export", "whitened"), "lburst.cli.export_whitened", "weights with descriptor whitening from training photos"),
    (("export", "weights"), "lburst.cli.export_weights", "a training run's checkpoint as shippable weights"),
]


#: Help of options that several commands share, for those that give none themselves.
SHARED_HELP = {
    "frame_order": "frame order for burst networks ('published' for the published LBurst weights)",
    "top_k": "keypoints per image (learned methods)",
    "device": "cpu or cuda (default: cuda if available)",
    "frames": "frames per burst (odd)",
    "seed": "random seed (a run with the same seed repeats)",
    "preset": "training recipe (lburst.train.loop.PRESETS)",
    "steps": "training steps (default: the preset's)",
    "batch_size": "bursts per step (default: the preset's)",
    "workers": "data loader processes (default: the preset's)",
    "methods": "feature method specs to compare (see lburst methods)",
    "max_side": "shrink images whose long side is longer than this, in pixels",
    "out": "output folder",
    "pairs": "image pairs to match (auto: exhaustive for up to 20 images, else sequential)",
    "overlap": "sequential pairs: neighbours on each side",
    "fallback_exhaustive": "rerun with all pairs when sequential pairs leave images unregistered",
    "mapper": "COLMAP's incremental mapper or the global one (GLOMAP)",
    "camera": "intrinsics prior: EXIF or default (auto), default, or the scene's reference.json",
    "camera_model": "COLMAP camera model of the priors",
    "threads": "COLMAP threads",
    "bursts": "number of bursts",
    "opset": "ONNX opset version",
}


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Each option's help ends with its default, unless the default is None or False or
    the help already says it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if (
            action.default in (None, False, argparse.SUPPRESS)
            or "default" in text
            or "%(default)" in text
            or (not action.option_strings and action.nargs not in ("?", "*"))
        ):
            return text
        return f"{text} (default: %(default)s)"


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("lburst")
    except PackageNotFoundError:
        return lburst.__version__


def _fill_help(parser: argparse.ArgumentParser) -> None:
    for action in parser._actions:
        if not action.help and action.dest in SHARED_HELP:
            action.help = SHARED_HELP[action.dest]


class UsageError(LBurstValueError):
    """A command line that the parser refuses (a bad option value, a missing argument, an
    unknown option); ``command`` names the (sub)command it was given to."""

    def __init__(self, command: str, message: str) -> None:
        super().__init__(message)
        self.command = command


class Parser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are :class:`UsageError`, printed by :func:`main` as
    one line like every error (``lburst extract: error: argument --every: ...``), not after the
    usage (``--help`` shows that).  Subcommands' parsers are of this class too."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(self.prog.removeprefix("lburst").strip(), message)


def build_parser(load: tuple[str, ...] | None = None) -> argparse.ArgumentParser:
    """The parser; only the subcommand ``load`` has its module imported for its options."""
    parser = Parser(
        prog="lburst",
        description="Features from low-light robotic bursts.",
        epilog=EXIT_STATUS,
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"lburst {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    groups: dict[str, argparse._SubParsersAction] = {}
    for words, module, help_text in COMMANDS:
        if len(words) == 1:
            target, name = sub, words[0]
        else:
            if words[0] not in groups:
                group = sub.add_parser(words[0], help=f"{words[0]} subcommands", formatter_class=HelpFormatter)
                group.set_defaults(_group=group)  # without a subcommand: this group's help
                groups[words[0]] = group.add_subparsers(dest="subcommand", metavar="SUBCOMMAND")
            target, name = groups[words[0]], words[1]
        p = target.add_parser(name, help=help_text, description=help_text, formatter_class=HelpFormatter)
        p.set_defaults(_module=module)
        if load == words:
            importlib.import_module(module).configure_parser(p)
            _fill_help(p)
    return parser


EXIT_STATUS = f"""\
exit status:
  {EXIT_OK}    finished
  {EXIT_FAILED}    ran, but some of its work failed (an input it skipped, no model, a model
       that fails its checks, a recording cut short); what it finished is kept
  {EXIT_BAD_INPUT}    did nothing: bad options or input (usage, a bad spec or value, a missing or
       unreadable file, a missing optional extra, an output folder in use)
  {EXIT_INTERRUPTED}  interrupted; finished work is kept and a re-run resumes

An error is one line on stderr, "lburst COMMAND: error: MESSAGE" (LBURST_TRACEBACK=1 shows
the traceback instead)."""


def error_line(exc: BaseException) -> str:
    """One line for an error from bad input or the operating system: an OSError names its
    file and says why (``PATH: Permission denied``), anything else is its message."""
    if isinstance(exc, OSError) and exc.strerror and exc.filename is not None:
        where = os.fsdecode(exc.filename) + (f" -> {os.fsdecode(exc.filename2)}" if exc.filename2 else "")
        return f"{where}: {exc.strerror}"
    text = str(exc) or type(exc).__name__
    return " ".join(text.split("\n")[:1]) if isinstance(exc, OSError) else text


def error_message(command: str, exc: BaseException | str) -> str:
    """The one format of every error the ``lburst`` command prints: ``lburst COMMAND: error: MESSAGE``."""
    text = exc if isinstance(exc, str) else error_line(exc)
    return f"lburst{' ' + command if command else ''}: error: {text}"


def exit_code(exc: BaseException) -> int:
    """The exit status for an error that ends a command (see :data:`EXIT_STATUS`)."""
    return getattr(exc, "exit_code", EXIT_BAD_INPUT) if isinstance(exc, LBurstError) else EXIT_BAD_INPUT


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    return f"lburst: warning: {message}\n"


def _words(argv: list[str]) -> tuple[str, ...] | None:
    for words, _, _ in COMMANDS:
        if tuple(argv[: len(words)]) == words:
            return words
    return None


def main(argv: list[str] | None = None) -> int:
    """The ``lburst`` command: its exit status, :data:`EXIT_STATUS`.  Every error that lburst
    raises on purpose (:class:`lburst.LBurstError`) and every ``ValueError`` or ``OSError``
    ends it here, printed as one line by :func:`error_message`.  Called in-process, it leaves
    the process as it found it: torch's threads and random state, the warnings format
    (:func:`lburst.process.state_kept`)."""
    with state_kept():
        return _main(argv)


def _main(argv: list[str] | None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    for stream in (sys.stdout, sys.stderr):  # file names that are not valid UTF-8 print escaped
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")
    warnings.formatwarning = _one_line_warning
    words = _words(argv)
    command = " ".join(words or argv[:1])
    try:
        parser = build_parser(words)
        args = parser.parse_args(argv)
        if not hasattr(args, "_module"):
            getattr(args, "_group", parser).print_help()
            return EXIT_BAD_INPUT
        module = importlib.import_module(args._module)
        return int(module.main(args) or EXIT_OK)
    except (LBurstError, OSError, ValueError) as exc:  # bad input, a failed run, the OS: one line, no traceback
        if os.environ.get("LBURST_TRACEBACK"):
            raise
        if isinstance(exc, UsageError):  # the subcommand whose parser refused, else the one named
            command = exc.command or " ".join(words or ())
        print(error_message(command, exc), file=sys.stderr)
        return exit_code(exc)
    except KeyboardInterrupt:
        print(
            f"lburst{' ' + command if command else ''}: interrupted; finished work is kept and a re-run resumes",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
