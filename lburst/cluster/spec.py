"""``--cluster``: where bursts run, as :class:`ClusterSpec` (:func:`parse_cluster`).

``local:N`` starts a cluster of ``N`` worker processes on this machine for the run;
``tcp://HOST:PORT`` (or ``tls://``) joins the scheduler of a running cluster
(``dask scheduler``, ``dask worker``: docs/large_surveys.md).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from lburst.errors import LBurstValueError

MAX_LOCAL_WORKERS = 1024
_LOCAL = re.compile(r"local:(\d+)")
_ADDRESS = re.compile(r"(tcp|tls)://([A-Za-z0-9.\-]+|\[[0-9A-Fa-f:]+\]):(\d+)")
EXPECTED = "expected local:N (N worker processes on this machine) or a scheduler address tcp://HOST:PORT"


@dataclass(frozen=True)
class ClusterSpec:
    """A local cluster of ``workers`` processes (``address`` ``None``), or the scheduler at ``address``."""

    workers: int | None = None
    address: str | None = None

    @property
    def local(self) -> bool:
        return self.address is None

    def __str__(self) -> str:
        return f"local:{self.workers}" if self.local else str(self.address)


def parse_cluster(text: str) -> ClusterSpec:
    """The :class:`ClusterSpec` of ``text``; :class:`lburst.errors.LBurstValueError` (one line)
    for anything else."""
    text = text.strip()
    if local := _LOCAL.fullmatch(text):
        workers = int(local.group(1))
        if not 1 <= workers <= MAX_LOCAL_WORKERS:
            raise LBurstValueError(f"--cluster {text!r}: a local cluster needs 1 to {MAX_LOCAL_WORKERS} workers")
        return ClusterSpec(workers=workers)
    if address := _ADDRESS.fullmatch(text):
        if not 1 <= int(address.group(3)) <= 65535:
            raise LBurstValueError(f"--cluster {text!r}: the port must be 1 to 65535")
        return ClusterSpec(address=text)
    raise LBurstValueError(f"--cluster {text!r}: {EXPECTED}")
