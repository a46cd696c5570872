"""Storage that Python can see is never freed or moved while a view of it is alive.

Every public member of GaussianCloud is classified below as reading or mutating; a new member
fails test_every_member_is_classified until it is. Each mutating member is then called while
views of every array are alive, and the views are written through afterwards. The arrays hold
10^6 values, so glibc serves them with mmap and a freed buffer is unmapped: a write through a
dangling view is a segmentation fault, which the child process reports as a negative return code.
"""
import os
import subprocess
import sys
import threading

import numpy as np
import pytest

import avsplat

MUTATING = {
    "means": "c.means = np.full((N, 3), 2.0, np.float32)",
    "scales": "c.scales = np.full((N, 3), 2.0, np.float32)",
    "rotations": "c.rotations = np.full((N, 4), 2.0, np.float32)",
    "opacities": "c.opacities = np.full(N, 0.5, np.float32)",
    "sh": "c.sh = np.full((N, 4, 3), 2.0, np.float32)",
    "confidence": "c.confidence = np.zeros(N, np.float32); c.confidence = None; c.confidence = np.ones(N)",
    "set_extra": "c.set_extra('e', np.zeros(N, np.float32)); c.set_extra('f', np.zeros(N, np.float32))",
    "sanitize": "c.opacities[::2] = np.nan; c.sanitize()",
    "antialiased": "c.antialiased = True",
}
READING = {"sh_degree", "sh_coeffs", "extras", "covariance", "bounding_box", "validate", "select",
           "select_mask", "copy", "empty", "from_open3d", "to_open3d", "to_open3d_legacy"}

CHILD = r'''
import sys, numpy as np, avsplat
N = 10**6
c = avsplat.GaussianCloud.empty(N, 1)
c.confidence = np.ones(N, np.float32)
c.set_extra('e', np.ones(N, np.float32))
views = [c.means, c.scales, c.rotations, c.opacities, c.sh, c.confidence, c.extras['e']]
exec(sys.argv[1])
for v in views:
    v[...] = 7
print(sum(float(v.ravel()[-1]) for v in views))
'''


def test_every_member_is_classified():
    public = {name for name in dir(avsplat.GaussianCloud) if not name.startswith("_")}
    assert public == set(MUTATING) | READING, "classify the new members as MUTATING or READING"


@pytest.mark.parametrize("member", sorted(MUTATING))
def test_views_stay_valid_across_a_mutation(member):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    p = subprocess.run([sys.executable, "-c", CHILD, MUTATING[member]], env=env, capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 0, (member, p.returncode, p.stderr[-2000:])
    assert float(p.stdout) == 7 * 7


def test_a_replaced_extra_channel_is_written_through_old_views():
    c = avsplat.GaussianCloud.empty(1000)
    c.set_extra("e", np.ones(1000, np.float32))
    v = c.extras["e"]
    c.set_extra("e", np.zeros(1000, np.float32))
    np.testing.assert_array_equal(v, 0)
    v[:] = 7
    np.testing.assert_array_equal(c.extras["e"], 7)


CONCURRENT = r'''
import sys, threading, numpy as np, avsplat
rng = np.random.default_rng(0)
n = 400000
c = avsplat.GaussianCloud(rng.normal(size=(n, 3)), np.full((n, 3), 0.01), np.tile([1.0, 0, 0, 0], (n, 1)),
                          np.full(n, 0.5), rng.normal(size=(n, 1, 3)))
c.set_extra('e', np.ones(n, np.float32))
refused = 0
for attempt in range(20):
    started = threading.Event()
    def fuse():
        started.set()
        for _ in range(3):
            avsplat.fuse_gaussians(c, 0.01)
    t = threading.Thread(target=fuse)
    t.start()
    started.wait()
    k = 0
    while t.is_alive():
        c.set_extra('e', np.full(n, k, np.float32))  # in place: allowed while in use
        try:
            c.set_extra('new%d_%d' % (attempt, k), np.zeros(n, np.float32))
        except RuntimeError as e:
            assert 'in use' in str(e), e
            refused += 1
        try:
            c.confidence = np.ones(n, np.float32)
            c.confidence = None
        except RuntimeError as e:
            assert 'in use' in str(e), e
            refused += 1
        k += 1
    t.join()
    if refused:
        break
print(refused)
'''


def test_layout_changes_are_refused_while_another_thread_reads_the_cloud():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    p = subprocess.run([sys.executable, "-c", CONCURRENT], env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, (p.returncode, p.stderr[-2000:])
    assert int(p.stdout) > 0


def test_a_cloud_is_free_again_after_the_call_returns():
    c = avsplat.GaussianCloud.empty(100)
    done = threading.Event()

    def fuse():
        avsplat.fuse_gaussians(c, 0.5)
        done.set()

    t = threading.Thread(target=fuse)
    t.start()
    t.join()
    assert done.is_set()
    c.set_extra("new", np.zeros(100, np.float32))  # no longer in use
    c.confidence = np.ones(100, np.float32)
    c.confidence = None


RELEASE_WHILE_RENDERING = r'''
import threading, numpy as np, avsplat
rng = np.random.default_rng(0)
n = 300000
c = avsplat.GaussianCloud(rng.normal(size=(n, 3)) + [0, 0, 4], np.full((n, 3), 0.05), np.tile([1.0, 0, 0, 0], (n, 1)),
                          np.full(n, 0.5), rng.normal(size=(n, 1, 3)))
cam = avsplat.Camera.look_at(np.array([0, 0, -2.0]), np.array([0, 0, 4.0]), np.array([0, -1, 0.0]), 60, 640, 480)
ws = avsplat.RenderWorkspace()
avsplat.render(c, cam, workspace=ws)
refused = 0
for attempt in range(20):
    t = threading.Thread(target=lambda: [avsplat.render(c, cam, workspace=ws) for _ in range(3)])
    t.start()
    while t.is_alive():
        try:
            ws.release()
        except RuntimeError as e:
            assert "in use" in str(e), e
            refused += 1
    t.join()
    if refused:
        break
print(refused)
'''


def test_a_render_workspace_is_not_released_under_a_running_render():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    p = subprocess.run([sys.executable, "-c", RELEASE_WHILE_RENDERING], env=env, capture_output=True, text=True,
                       timeout=600)
    assert p.returncode == 0, (p.returncode, p.stderr[-2000:])
    assert int(p.stdout) > 0
