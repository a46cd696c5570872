"""One version number: CMake's project(VERSION) is what `avsplat --version`, avsplat.__version__
and the installed CMake package report."""
import os
import re
import subprocess

import avsplat

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.path.join(ROOT, "build", "apps", "avsplat")


def cmake_project_version():
    text = open(os.path.join(ROOT, "CMakeLists.txt")).read()
    return re.search(r"project\(avsplat\s+VERSION\s+([0-9.]+)", text).group(1)


def test_python_version_is_cmake_project_version():
    assert avsplat.__version__ == cmake_project_version()
    assert avsplat._avsplat.__version__ == avsplat.__version__


def test_cli_version_agrees_with_python():
    r = subprocess.run([BIN, "--version"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == avsplat.__version__


def test_changelog_names_the_version():
    changelog = open(os.path.join(ROOT, "CHANGELOG.md")).read()
    assert re.search(r"^## \[?" + re.escape(avsplat.__version__) + r"\b", changelog, flags=re.M)
