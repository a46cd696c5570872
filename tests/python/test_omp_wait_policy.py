"""The tool and the module make idle OpenMP threads sleep (OMP_WAIT_POLICY=PASSIVE) by default.

What libgomp read is observed directly: with OMP_DISPLAY_ENV=VERBOSE it prints its settings when
it initialises, GOMP_SPINCOUNT among them (0 for PASSIVE, 300000 when no policy is set,
30000000000 for ACTIVE). A user's own choice is kept.
"""

import os
import re
import subprocess
import sys

import pytest

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")
PYTHONPATH = os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__)))


def spincount(cmd, policy):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMP_", "GOMP_"))}
    env["OMP_DISPLAY_ENV"] = "VERBOSE"
    env["PYTHONPATH"] = PYTHONPATH
    if policy is not None:
        env["OMP_WAIT_POLICY"] = policy
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 0, p.stderr
    m = re.search(r"GOMP_SPINCOUNT = '(\d+)'", p.stderr)
    if m is None:
        pytest.skip("the OpenMP runtime is not libgomp (no GOMP_SPINCOUNT in OMP_DISPLAY_ENV)")
    return int(m.group(1))


@pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")
def test_cli_defaults_to_passive_and_keeps_the_users_policy():
    assert spincount([BIN, "--help"], None) == 0
    assert spincount([BIN, "--help"], "ACTIVE") > 300000
    assert spincount([BIN, "--help"], "passive") == 0


def test_python_module_defaults_to_passive_and_keeps_the_users_policy():
    code = "import avsplat, os; assert os.environ['OMP_WAIT_POLICY']"
    assert spincount([sys.executable, "-c", code], None) == 0
    assert spincount([sys.executable, "-c", code], "ACTIVE") > 300000
