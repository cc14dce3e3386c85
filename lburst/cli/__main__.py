"""``python -m lburst.cli ...`` (as under ``torchrun``): the ``lburst`` command."""

import sys

from lburst.cli import main

sys.exit(main())
