"""``python3 -m avsplat.evaluation``: the same as ``python3 -m avsplat.eval``."""

import sys

from avsplat.eval import main

sys.exit(main())
