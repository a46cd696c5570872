"""Allocation failure under a memory limit (RLIMIT_AS, as `ulimit -v`): MemoryError, never a crash.

Each function runs in a subprocess that builds its input, then, for a sweep of margins, limits
its address space to what it uses already plus the margin (the soft limit; it is lifted again
between calls) and calls the function. The margins step from "fails at the first allocation" to
"succeeds", so that allocations inside OpenMP regions (per-thread buffers, outputs zero-filled by
one thread while the others work) fail too. Before the fix, some margins ended the process with
"terminate called after throwing an instance of 'std::bad_alloc'", and a limit set after import
ended it with "libgomp: Thread creation failed".
"""
import os
import subprocess
import sys

import numpy as np
import pytest

import avsplat

PYTHONPATH = os.path.dirname(os.path.dirname(avsplat.__file__))

SCRIPT = r"""
import ctypes, resource, sys
import numpy as np
import avsplat
what = sys.argv[1]
n = 300_000
rng = np.random.default_rng(0)
pts = rng.uniform(0, 1, (n, 3)).astype(np.float32)
feats = rng.uniform(0, 1, (n, 16)).astype(np.float32)
cloud = avsplat.GaussianCloud(pts + [0, 0, 2], np.full((n, 3), 0.01), np.tile([1.0, 0, 0, 0], (n, 1)),
                              np.full(n, 0.5), rng.uniform(0, 1, (n, 4, 3)))
cam = avsplat.Camera(300, 300, 320, 240, 640, 480)
calls = {
    "fuse_voxels": lambda: avsplat.fuse_voxels(pts, feats, 0.001),
    "fuse_gaussians": lambda: avsplat.fuse_gaussians(cloud, 0.001, policy="softmax"),
    "render": lambda: avsplat.render(cloud, cam),
    "gaussians_from_point_maps": lambda: avsplat.gaussians_from_point_maps(pts[:50_000], pts[:50_000]),
}
_, hard = resource.getrlimit(resource.RLIMIT_AS)
outcomes = []
for margin_mb in (-64, 0, 2, 4, 8, 12, 16, 24, 32, 48, 64, 96, 256, 1024):
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    vm = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmSize:")) * 1024
    resource.setrlimit(resource.RLIMIT_AS, (max(vm + margin_mb * 2**20, 2**20), hard))
    try:
        calls[what]()
        outcomes.append("ok")
    except MemoryError:
        outcomes.append("MemoryError")
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (hard, hard))
print(" ".join(outcomes))
"""


@pytest.mark.parametrize("what", ["fuse_voxels", "fuse_gaussians", "render", "gaussians_from_point_maps"])
def test_allocation_failure_is_memory_error_at_every_margin(what):
    p = subprocess.run([sys.executable, "-c", SCRIPT, what], capture_output=True, text=True, timeout=300,
                       # A fixed mmap threshold: large blocks always come from new mappings, which
                       # the limit refuses, rather than from heap memory freed by earlier steps.
                       env={**os.environ, "PYTHONPATH": PYTHONPATH, "MALLOC_MMAP_THRESHOLD_": "131072"})
    assert p.returncode == 0, p.stderr[-800:]
    outcomes = p.stdout.split()
    assert set(outcomes) <= {"ok", "MemoryError"}, p.stdout
    # The sweep reached the failure paths, and a failed call leaves nothing behind that stops a
    # later one with enough memory. (Outcomes need not be monotonic in the margin: the heap reuses
    # memory freed by earlier calls.)
    assert "MemoryError" in outcomes and outcomes[-1] == "ok", outcomes


def test_image_sizes_whose_arithmetic_overflows_are_value_errors_before_allocating():
    cloud = avsplat.GaussianCloud(np.array([[0.0, 0, 3]]), np.full((1, 3), 0.1), np.array([[1.0, 0, 0, 0]]),
                                  np.ones(1), np.zeros((1, 1, 3)))
    with pytest.raises(ValueError, match=r"1000000 x 1000000 needs 3906250000 tiles"):
        avsplat.render(cloud, avsplat.Camera(100, 100, 5e5, 5e5, 1_000_000, 1_000_000))
    with pytest.raises(ValueError, match=r"at most 2\^24 pixels per side"):
        avsplat.render(cloud, avsplat.Camera(100, 100, 1, 1, 2**31 - 1, 1))
