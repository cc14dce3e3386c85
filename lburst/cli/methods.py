"""``lburst methods``: every feature method and matcher, with its options and defaults."""

from __future__ import annotations

import argparse

from lburst import matching, methods
from lburst.errors import LBurstValueError
from lburst.methods.options import format_default, option_table


def configure_parser(p: argparse.ArgumentParser) -> None:
    p.add_argument("name", nargs="?", help="show only this method or matcher")


def _entry(form: str, summary: str, options: type | None) -> list[str]:
    lines = [f"  {form}", f"      {summary}"]
    table = option_table(options)
    if not table:
        lines.append("      no options")
    for name, type_name, default in table:
        lines.append(f"      {name}={format_default(default)}  ({type_name})")
    return lines


def listing(name: str | None = None) -> str:
    """The text of ``lburst methods [NAME]``."""
    out = ["Feature methods (--method SPEC: NAME[:ARG][,KEY=VALUE...]; a wrapper: NAME[,KEY=VALUE]+SPEC):"]
    for info in methods.methods():
        if name in (None, info.name):
            form = (
                f"{info.name}[,KEY=VALUE...]+SPEC"
                if info.wraps
                else info.name + (f"[:{info.arg.upper()}]" if info.arg else "") + "[,KEY=VALUE...]"
            )
            out += _entry(form, info.summary, info.options)
    out += ["", "Matchers (--matcher SPEC: NAME[,KEY=VALUE...]):"]
    for info in matching.available():
        if name in (None, info.name):
            out += _entry(f"{info.name}[,KEY=VALUE...]", info.summary, info.options)
    return "\n".join(out)


def main(args: argparse.Namespace) -> int:
    known = set(methods.available()) | {m.name for m in matching.available()}
    if args.name is not None and args.name not in known:
        raise LBurstValueError(f"unknown method or matcher {args.name!r}; known: {', '.join(sorted(known))}")
    print(listing(args.name))
    return 0
