"""Makes the build tree's package importable when PYTHONPATH is not set."""
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BUILD_PYTHON = os.path.join(ROOT, "build", "python")
if not any(os.path.isfile(os.path.join(p, "avsplat", "__init__.py")) for p in sys.path if p):
    sys.path.insert(0, BUILD_PYTHON)
