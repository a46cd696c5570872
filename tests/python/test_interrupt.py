"""Ctrl-C during long calls: the call stops early with the exception the SIGINT handler raised.

A timer thread raises SIGINT in the process (os.kill) half way through a call, timed from an
uninterrupted run of the same call. A test-local handler raises Stop instead of
KeyboardInterrupt, so that a late signal can fail only this test, never end the pytest run.
Python runs the handler either from inside the C++ call (the interrupt check polls it about
every 0.1 s) or, if the call ignored the signal, only when the call returns, half the call's time
later. The tests tell the two apart by that delay, with the call sized to take about a second or
more so that the margin is several times the poll interval.
"""
import os
import signal
import subprocess
import threading
import time

import numpy as np
import pytest

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")


class Stop(Exception):
    pass


def interrupted(call, after):
    """Runs call() with SIGINT sent `after` seconds in. Returns (result or None, raised Stop,
    seconds from the signal to the handler's run)."""
    sent, handled = [], []

    def handler(signum, frame):
        handled.append(time.perf_counter())
        raise Stop()

    def send():
        sent.append(time.perf_counter())
        os.kill(os.getpid(), signal.SIGINT)

    previous = signal.signal(signal.SIGINT, handler)
    timer = threading.Timer(after, send)
    result, stopped = None, False
    try:
        timer.start()
        try:
            result = call()
        except Stop:
            stopped = True
        try:
            timer.join()
            time.sleep(0.05)  # a late signal is handled here, inside this try
        except Stop:
            pass
    finally:
        signal.signal(signal.SIGINT, previous)
    return result, stopped, handled[0] - sent[0]


def timed(call):
    t0 = time.perf_counter()
    result = call()
    return result, time.perf_counter() - t0


def big_fusion_input(n=8_000_000, seed=0):
    rng = np.random.default_rng(seed)
    return avsplat.GaussianCloud(rng.uniform(0, 1, (n, 3)), np.full((n, 3), 0.01), np.tile([1.0, 0, 0, 0], (n, 1)),
                                 np.full(n, 0.5), rng.uniform(0, 1, (n, 1, 3)))


def heavy_render_scene(m=20000, seed=0):
    """Large, faint Gaussians that all cover the image: every pixel blends ~1800 of them."""
    rng = np.random.default_rng(seed)
    return avsplat.GaussianCloud(rng.normal(0, 0.1, (m, 3)) + [0, 0, 3], np.full((m, 3), 2.0),
                                 np.tile([1.0, 0, 0, 0], (m, 1)), np.full(m, 0.005), rng.uniform(0, 1, (m, 1, 3)))


def test_fusion_stops_on_ctrl_c_and_runs_normally_afterwards():
    cloud = big_fusion_input()
    call = lambda: avsplat.fuse_gaussians(cloud, 0.02, policy="occupancy")  # noqa: E731
    reference, seconds = timed(call)
    result, stopped, delay = interrupted(call, seconds / 2)
    assert stopped and result is None
    assert delay < seconds / 4, (delay, seconds)  # handled inside the call, not after it
    again = call()  # nothing left over from the interrupted call
    np.testing.assert_array_equal(again.cloud.means, reference.cloud.means)
    np.testing.assert_array_equal(again.cloud.sh, reference.cloud.sh)


def test_render_stops_on_ctrl_c():
    cloud = heavy_render_scene()
    cam = avsplat.Camera(600, 600, 384, 288, 768, 576)
    call = lambda: avsplat.render(cloud, cam)  # noqa: E731
    reference, seconds = timed(call)
    result, stopped, delay = interrupted(call, seconds / 2)
    assert stopped and result is None
    assert delay < seconds / 4, (delay, seconds)
    np.testing.assert_array_equal(call().color, reference.color)


def test_keyboard_interrupt_is_what_the_default_handler_raises():
    # With Python's own SIGINT handler the call raises KeyboardInterrupt (run in a subprocess:
    # a KeyboardInterrupt here would end the test run).
    code = f"""
import os, signal, sys, threading, time
sys.path.insert(0, {os.path.dirname(os.path.dirname(avsplat.__file__))!r})
import numpy as np, avsplat
rng = np.random.default_rng(0)
m = 20000
cloud = avsplat.GaussianCloud(rng.normal(0, 0.1, (m, 3)) + [0, 0, 3], np.full((m, 3), 2.0),
                              np.tile([1.0, 0, 0, 0], (m, 1)), np.full(m, 0.005), rng.uniform(0, 1, (m, 1, 3)))
cam = avsplat.Camera(800, 800, 512, 384, 1024, 768)
threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT)).start()
t0 = time.perf_counter()
try:
    avsplat.render(cloud, cam)
except KeyboardInterrupt:
    # The uninterrupted call takes ~10 s on a 2-core machine (stats.blends ~ 6.9e9).
    print("KeyboardInterrupt", time.perf_counter() - t0 < 3.0)
"""
    p = subprocess.run(["/usr/bin/python3", "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "KeyboardInterrupt True"


@pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")
@pytest.mark.parametrize("signum,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_cli_stops_on_sigint_and_sigterm_without_partial_output(tmp_path, signum, code):
    scene = tmp_path / "scene.ply"
    avsplat.write_ply(str(scene), heavy_render_scene())
    cams = tmp_path / "cams.json"
    avsplat.write_cameras_json(str(cams), [avsplat.Camera(800, 800, 512, 384, 1024, 768)])
    out = tmp_path / "out.png"
    out.write_bytes(b"the user's old image")
    p = subprocess.Popen([BIN, "render", str(scene), "--camera", str(cams), "-o", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.5)
    p.send_signal(signum)
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == code, stderr
    assert "interrupted by" in stderr and stdout == ""
    assert out.read_bytes() == b"the user's old image"
    assert sorted(f.name for f in tmp_path.iterdir()) == ["cams.json", "out.png", "scene.ply"]
