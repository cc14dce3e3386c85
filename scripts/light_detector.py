"""``lburst`` with lburst-b5's keypoints chosen by the light network: every pyramid level's
repeatability and reliability come from the shipped lburst-b5-lite on the same input, the
descriptors from lburst-b5's own map.  Both networks read the aligned 5-frame burst, so the level
is the same tensor for both.  Everything else (the pipeline, the command line) is the ``lburst``
command's, e.g. how far the light network's detector shrinks lburst-b5's loss under noise:

    python scripts/light_detector.py bench homography data/validation --every 4 --sigma 0 100 \
        --methods lburst --out outputs/val_light_detector

With ``--repeatability-only`` first, only the repeatability is the light network's; the
reliability stays lburst-b5's, the gate trained on lburst-b5's own descriptors.

The swap applies on the fast path of every network but the light one, in this process only.
"""

from __future__ import annotations

import functools
import sys

from lburst.cli import main
from lburst.model.extractor import LBurst
from lburst.model.lite import LiteNet

_network_level = LBurst._fast_level


@functools.cache
def light_detector() -> LBurst:
    """The shipped light network in torch (fp32), loaded once."""
    return LBurst.pretrained("lburst-b5-lite", device="cpu", runtime="torch")


def _light_level(self: LBurst, x, precision: str, light_reliability: bool):
    """The light network's repeatability (and reliability, with ``light_reliability``), this
    network's descriptor map (and reliability, without)."""
    if isinstance(self.net, LiteNet):
        return _network_level(self, x, precision)
    repeatability, light, _ = _network_level(light_detector(), x, "fp32")
    _, own, descriptors = _network_level(self, x, precision)
    return repeatability, light if light_reliability else own, descriptors


def _light_detector_level(self: LBurst, x, precision: str):
    """The light network's repeatability and reliability, this network's descriptor map."""
    return _light_level(self, x, precision, light_reliability=True)


def _light_repeatability_level(self: LBurst, x, precision: str):
    """The light network's repeatability, this network's reliability and descriptor map."""
    return _light_level(self, x, precision, light_reliability=False)


if __name__ == "__main__":
    args = sys.argv[1:]
    only = bool(args) and args[0] == "--repeatability-only"
    LBurst._fast_level = _light_repeatability_level if only else _light_detector_level
    sys.exit(main(args[1:] if only else args))
