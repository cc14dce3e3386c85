"""The ``lburst`` command line.  Each subcommand lives in one module, which defines
``configure_parser(parser)`` (its options) and ``main(args) -> int`` (its exit code);
this file only wires them up, importing a module when its subcommand runs."""

from __future__ import annotations

import argparse
import importlib
import sys

# (subcommand words, module, one-line help)
COMMANDS: list[tuple[tuple[str, ...], str, str]] = [
    (("extract",), "lburst.commands.extract", "features of bursts to .npz (and hloc features.h5)"),
    (("show",), "lburst.commands.show", "picture of a burst's keypoints and confidence maps"),
    (("methods",), "lburst.commands.methods", "feature methods and matchers, with their options and defaults"),
    (("simulate", "burst"), "lburst.commands.simulate", "a low-light burst from one photo"),
    (("simulate", "scene"), "lburst.scenes.photo_scene", "a low-light burst scene from a multi-view photo set"),
    (("simulate", "sequences"), "lburst.bench.validation", "HPatches-style homography sequences from photos"),
    (("simulate", "flight"), "lburst.scenes.night_flight", "the synthetic night flight scene with exact ground truth"),
    (("train",), "lburst.train.loop", "self-supervised training of a burst (or single-image) network"),
    (("bench", "homography"), "lburst.bench.homography", "noisy-burst homography benchmark (MMA, repeatability)"),
    (("bench", "reconstruction"), "lburst.bench.reconstruction", "reconstruction benchmark on burst scenes"),
    (("reconstruct",), "lburst.sfm.reconstruct", "a 3D model of a burst scene with COLMAP"),
    (("demo",), "lburst.demo", "synthetic night flight: LBurst vs SIFT, with a report"),
    (("export", "onnx"), "lburst.export_onnx", "export a network to ONNX"),
]


def build_parser(load: tuple[str, ...] | None = None) -> argparse.ArgumentParser:
    """The parser; only the subcommand ``load`` has its module imported for its options."""
    parser = argparse.ArgumentParser(prog="lburst", description="Features from low-light robotic bursts.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    groups: dict[str, argparse._SubParsersAction] = {}
    for words, module, help_text in COMMANDS:
        if len(words) == 1:
            target, name = sub, words[0]
        else:
            if words[0] not in groups:
                group = sub.add_parser(words[0], help=f"{words[0]} subcommands")
                groups[words[0]] = group.add_subparsers(dest="subcommand", metavar="SUBCOMMAND")
            target, name = groups[words[0]], words[1]
        p = target.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(_module=module)
        if load == words:
            importlib.import_module(module).configure_parser(p)
    return parser


def _words(argv: list[str]) -> tuple[str, ...] | None:
    for words, _, _ in COMMANDS:
        if tuple(argv[: len(words)]) == words:
            return words
    return None


def main(argv: list[str] | None = None) -> int:
    from lburst.extras import MissingExtra

    argv = sys.argv[1:] if argv is None else argv
    try:
        parser = build_parser(_words(argv))
        args = parser.parse_args(argv)
        if not hasattr(args, "_module"):
            parser.print_help()
            return 2
        module = importlib.import_module(args._module)
        return int(module.main(args) or 0)
    except MissingExtra as exc:  # an optional dependency: the message names the extra to install
        print(f"lburst: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted; finished work is kept and a re-run resumes", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
