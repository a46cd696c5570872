"""Makes the build tree's package importable when PYTHONPATH is not set."""
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BUILD_PYTHON = os.path.join(ROOT, "build", "python")
if not any(os.path.isfile(os.path.join(p, "avsplat", "__init__.py")) for p in sys.path if p):
    sys.path.insert(0, BUILD_PYTHON)


import shutil  # noqa: E402
import subprocess  # noqa: E402

import pytest  # noqa: E402

SPLAT_TRANSFORM_SCRIPT = os.path.join(ROOT, "scripts", "splat_transform.sh")


@pytest.fixture(scope="session")
def splat_transform():
    """PlayCanvas's splat-transform 3.7.0, the independent peer for formats and reduction.

    Returns run(*args, timeout=600) -> subprocess.CompletedProcess, which runs
    `splat-transform -q -w -g cpu ARGS...` and fails the test with its stderr when it exits
    non-zero. Installed on first use by scripts/splat_transform.sh into build-node/ (ignored);
    skips only when npm is absent, and fails when npm is there but the install fails."""
    if shutil.which("npm") is None:
        pytest.skip("npm is not installed, so PlayCanvas's splat-transform cannot be installed")
    done = subprocess.run(["bash", SPLAT_TRANSFORM_SCRIPT], capture_output=True, text=True)
    assert done.returncode == 0, "scripts/splat_transform.sh failed:\n" + done.stderr
    exe = done.stdout.strip().splitlines()[-1]

    def run(*args, timeout=600):
        cmd = [exe, "-q", "-w", "-g", "cpu", *map(str, args)]
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        assert r.returncode == 0, f"{' '.join(cmd)} exited {r.returncode}:\n{r.stderr}\n{r.stdout}"
        return r

    return run
