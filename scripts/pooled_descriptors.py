"""``lburst`` with every network's raw descriptor map average-pooled by 2 before the
descriptors are sampled: lburst-b5's half-resolution map becomes a quarter-resolution one, the
resolution of the light network's (:mod:`lburst.model.lite`).  Everything else (keypoints,
scores, the pipeline, the command line) is the ``lburst`` command's, so any benchmark can be run
on the pooled descriptors, e.g. how much of lburst-b5's lead on Oxford's zoom and viewpoint
pairs rests on its descriptors' resolution:

    python scripts/pooled_descriptors.py bench homography $LBURST_SHARED/data/homography --sigma 50 \
        --methods lburst --out outputs/ox50_b5_pooled

The pooling is applied on the fast path (every shipped network's default), in this process only.
"""

from __future__ import annotations

import sys

import torch.nn.functional as F

from lburst.cli import main
from lburst.model.extractor import LBurst

_network_level = LBurst._fast_level


def _pooled_level(self: LBurst, x, precision: str):
    """The network's ``(repeatability, reliability, descriptor map)`` with the map pooled by 2."""
    repeatability, reliability, descriptors = _network_level(self, x, precision)
    return repeatability, reliability, F.avg_pool2d(descriptors, 2, ceil_mode=True)


if __name__ == "__main__":
    LBurst._fast_level = _pooled_level
    sys.exit(main(sys.argv[1:]))
