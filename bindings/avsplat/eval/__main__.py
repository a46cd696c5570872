"""`python -m avsplat.eval REPORT -o DIR [--quick]` (what `avsplat eval` runs)."""

import sys

from . import main

sys.exit(main())
