"""The COLMAP child process: ``python -m lburst.cli.colmap_job JOB_DIR [--parent PID]`` runs one
job folder (:func:`lburst.sfm.colmap.run_job`; internal to ``lburst reconstruct``).  It imports
no torch, OpenCV or tqdm."""

from __future__ import annotations

import argparse
import logging
import sys

from lburst.cli.numbers import integer
from lburst.process import die_with_parent
from lburst.sfm.colmap import run_job


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Run one COLMAP job folder (internal to lburst reconstruct).")
    parser.add_argument("job_dir")
    parser.add_argument("--parent", type=integer(1), help="die when this process does (the lburst parent)")
    args = parser.parse_args(argv)
    if args.parent:
        die_with_parent(args.parent)
    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")  # to colmap.log (e.g. models joined)
    run_job(args.job_dir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
