"""Builds the extension avsplat._avsplat and the avsplat command-line tool with CMake.

setuptools only packages: CMake (the project's own CMakeLists.txt) compiles, for the Python that
runs this file, into build-pip-<python tag>/ of the source tree, so a second install rebuilds
only what changed and a fresh build directory still hits ccache: CCACHE_BASEDIR is the source
tree, and ccache rewrites paths relative to the build folder, so this one sits at the depth of
build/ (the compile commands, and so the cache keys, are then the same). The wheel holds the pure-Python package (with py.typed and the .pyi stubs), the compiled
module, and the tool at avsplat/_bin/avsplat, which the console script `avsplat` runs.

Environment: CMAKE_ARGS (extra -D options, split on spaces), CMAKE_BUILD_PARALLEL_LEVEL (jobs;
default all cores).
"""
import os
import pathlib
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig

from setuptools import Extension, find_packages, setup
from setuptools.command.build_ext import build_ext

ROOT = pathlib.Path(__file__).resolve().parent
(ROOT / "build" / "pip-setuptools").mkdir(parents=True, exist_ok=True)  # setup.cfg's egg_base


def project_version():
    text = (ROOT / "CMakeLists.txt").read_text()
    match = re.search(r"project\(avsplat VERSION ([0-9.]+)", text)
    if not match:
        raise RuntimeError("CMakeLists.txt: project(avsplat VERSION x.y.z) not found")
    return match.group(1)


class CMakeBuild(build_ext):
    """Configures and builds the targets _avsplat and avsplat_cli, then copies them into place."""

    def build_extension(self, ext):
        tag = sys.implementation.cache_tag  # e.g. cpython-311
        build_dir = ROOT / f"build-pip-{tag}"
        build_dir.mkdir(parents=True, exist_ok=True)
        configure = [
            "cmake", "-S", str(ROOT), "-B", str(build_dir),
            "-DCMAKE_BUILD_TYPE=Release",
            f"-DPython_EXECUTABLE={sys.executable}",
            "-DPYBIND11_FINDPYTHON=ON",
            "-DAVSPLAT_WITH_PYTHON=ON", "-DAVSPLAT_BUILD_APPS=ON",
            "-DAVSPLAT_BUILD_TESTS=OFF", "-DAVSPLAT_BUILD_BENCHMARKS=OFF", "-DAVSPLAT_BUILD_FUZZERS=OFF",
        ] + shlex.split(os.environ.get("CMAKE_ARGS", ""))
        subprocess.run(configure, check=True, stdout=subprocess.DEVNULL)
        jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL") or str(os.cpu_count() or 1)
        subprocess.run(["cmake", "--build", str(build_dir), "-j", jobs, "--target", "_avsplat", "avsplat_cli"],
                       check=True)

        suffix = sysconfig.get_config_var("EXT_SUFFIX")
        module = build_dir / "python" / "avsplat" / f"_avsplat{suffix}"
        if not module.is_file():
            raise RuntimeError(f"CMake built no {module.name} in {module.parent}")
        target = pathlib.Path(self.get_ext_fullpath(ext.name))
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(module, target)

        tool = build_dir / "apps" / "avsplat"
        tool_target = target.parent / "_bin" / "avsplat"
        tool_target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(tool, tool_target)


setup(
    version=project_version(),
    package_dir={"": "bindings"},
    packages=find_packages("bindings"),
    package_data={"avsplat": ["py.typed", "*.pyi"]},
    ext_modules=[Extension("avsplat._avsplat", sources=[])],
    cmdclass={"build_ext": CMakeBuild},
    zip_safe=False,
)
