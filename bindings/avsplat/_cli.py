"""The `avsplat` console script of a pip-installed package: runs the C++ tool installed beside it.

The tool is avsplat/_bin/avsplat; this process is replaced by it (exec), so its output, errors
and exit code are the tool's. AVSPLAT_PYTHON_DIR tells `avsplat eval` where this package is
(unless the caller chose one), and that interpreter runs it.
"""
import os
import pathlib
import sys


def main():
    """Replaces this process by the avsplat tool, with this interpreter's arguments."""
    package = pathlib.Path(__file__).resolve().parent
    tool = package / "_bin" / "avsplat"
    if not os.access(tool, os.X_OK):
        sys.exit(f"avsplat: the command-line tool {tool} is missing or not executable; reinstall avsplat")
    env = dict(os.environ)
    env.setdefault("AVSPLAT_PYTHON_DIR", str(package.parent))
    env.setdefault("AVSPLAT_PYTHON_EXECUTABLE", sys.executable)
    sys.stdout.flush()
    os.execve(tool, [str(tool)] + sys.argv[1:], env)
