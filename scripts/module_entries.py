"""Which lburst modules one command passes through, in the order it first enters them, and how
often each is entered: a call into a function of module M from code outside M.

    python scripts/module_entries.py --out entries.json -- reconstruct flight.mp4 --out rec --every 12

The command runs in this process (``lburst.cli.main``) under :func:`sys.setprofile` (every
thread).  Work that runs in other processes (COLMAP's child process, Dask workers) is not seen:
the table is what the calling process walks through.  ``climbs`` counts the calls from a module
outside ``lburst.cli`` into ``lburst.cli``: library code that needs the command line's steps.
Prints a markdown table; ``--out`` writes the counts as JSON.
"""

from __future__ import annotations

import argparse
import inspect
import json
import sys
import threading
from collections import Counter
from pathlib import Path


def trace(argv: list[str]) -> tuple[Counter, list[str], int, int]:
    """Run ``lburst ARGV`` here; return the entries per module, the modules in order of first
    entry, the climbs into ``lburst.cli`` and the command's exit status."""
    import lburst
    from lburst.cli import main

    root = str(Path(lburst.__file__).parent)
    entries: Counter = Counter()
    order: list[str] = []
    climbs = 0

    def hook(frame, event, _arg):
        nonlocal climbs
        if event != "call" or not frame.f_code.co_flags & inspect.CO_OPTIMIZED:
            return  # a module's or a class's body runs on import: not an entry
        module = frame.f_globals.get("__name__", "")
        if not module.startswith("lburst") or not frame.f_code.co_filename.startswith(root):
            return  # code that dataclasses and the like generate runs with the module's globals
        back = frame.f_back
        caller = back.f_globals.get("__name__", "") if back is not None else ""
        if caller == module:
            return
        if module not in entries:
            order.append(module)
        entries[module] += 1
        if module.startswith("lburst.cli") and caller.startswith("lburst") and not caller.startswith("lburst.cli"):
            climbs += 1

    threading.setprofile(hook)
    sys.setprofile(hook)
    try:
        status = main(argv)
    except SystemExit as exit_:
        status = exit_.code
    finally:
        sys.setprofile(None)
        threading.setprofile(None)
    return entries, order, climbs, int(status or 0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="write the counts here as JSON")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="-- then the lburst command's arguments")
    args = parser.parse_args()
    argv = args.command[1:] if args.command[:1] == ["--"] else args.command
    entries, order, climbs, status = trace(argv)
    print(
        f"\n`lburst {' '.join(argv)}`: exit {status}, {len(order)} modules, {sum(entries.values())} entries, "
        f"{climbs} climbs into lburst.cli\n"
    )
    print("| # | module | entries |\n|---|---|---|")
    for i, module in enumerate(order, 1):
        print(f"| {i} | `{module}` | {entries[module]} |")
    if args.out:
        data = {"argv": argv, "status": status, "order": order, "entries": dict(entries), "climbs": climbs}
        args.out.write_text(json.dumps(data, indent=1) + "\n")


if __name__ == "__main__":
    main()
