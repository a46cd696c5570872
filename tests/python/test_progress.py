"""progress= of the long operators and the CLI's bars: reports from the calling thread, first
(0, total), never decreasing, last (total, total); an exception raised by the callback stops the
work and comes out of the call; results identical with and without a callback; the CLI draws a
bar on a terminal only, and nothing with --quiet."""
import os
import re
import subprocess

import numpy as np
import pytest

import avsplat

BUILD = os.path.join(os.path.dirname(__file__), "..", "..", "build")
BIN = os.path.join(BUILD, "apps", "avsplat")


class Stop(Exception):
    pass


def recorder():
    calls = []
    return calls, lambda done, total: calls.append((done, total))


def check_reports(calls, total):
    assert calls, "the callback was never called"
    assert calls[0] == (0, total) and calls[-1] == (total, total)
    assert all(t == total for _, t in calls)
    done = [d for d, _ in calls]
    assert done == sorted(done)


def stop_at_first_step(done, total):
    if done > 0:
        raise Stop(f"stopped at {done}/{total}")


@pytest.fixture(scope="module")
def samples():
    return avsplat.simulate_predictions(views=8, width=96, height=72, seed=3).gaussians()


def same_cloud(a, b):
    for name in ("means", "scales", "rotations", "opacities", "sh"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_fuse_gaussians_reports_samples_fused(samples):
    calls, progress = recorder()
    with_progress = avsplat.fuse_gaussians(samples, 0.01, policy="occupancy", progress=progress)
    check_reports(calls, len(samples))
    assert len(calls) > 10  # sliced: reports along the fusion, not only at its ends
    same_cloud(with_progress.cloud, avsplat.fuse_gaussians(samples, 0.01, policy="occupancy").cloud)
    np.testing.assert_array_equal(with_progress.temperature,
                                  avsplat.fuse_gaussians(samples, 0.01, policy="occupancy").temperature)


def test_fuse_gaussians_reports_the_same_for_any_thread_count(samples, monkeypatch):
    # The reports are fixed by the input: the same sequence with one thread (run in a child so
    # that OMP_NUM_THREADS applies) as with all of them.
    calls, progress = recorder()
    avsplat.fuse_gaussians(samples, 0.01, progress=progress)
    path = os.path.join(os.path.dirname(avsplat.__file__), "..")
    code = ("import avsplat; c = avsplat.simulate_predictions(views=8, width=96, height=72, seed=3).gaussians(); "
            "r = []; avsplat.fuse_gaussians(c, 0.01, progress=lambda d, t: r.append((d, t))); print(r)")
    out = subprocess.run(["/usr/bin/python3", "-c", code], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": path})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str(calls)


def test_fuse_voxels_reports_start_and_end(samples):
    calls, progress = recorder()
    p = samples.means
    f = samples.sh.reshape(len(samples), -1)
    r = avsplat.fuse_voxels(p, f, 0.02, confidence=samples.confidence, progress=progress)
    check_reports(calls, len(samples))
    np.testing.assert_array_equal(r.features, avsplat.fuse_voxels(p, f, 0.02, confidence=samples.confidence).features)


def test_an_exception_in_the_callback_stops_fusion_and_propagates(samples):
    with pytest.raises(Stop, match="stopped at"):
        avsplat.fuse_gaussians(samples, 0.01, progress=stop_at_first_step)
    def refuse(done, total):
        raise Stop("at once")

    with pytest.raises(Stop, match="at once"):  # raised by the very first report, (0, total)
        avsplat.fuse_voxels(samples.means, samples.sh.reshape(len(samples), -1), 0.02, progress=refuse)
    # Nothing stays installed: the next call without a callback runs to the end.
    assert len(avsplat.fuse_gaussians(samples, 0.01).cloud) > 0


def test_progress_must_be_callable(samples):
    with pytest.raises(TypeError, match="progress"):
        avsplat.fuse_gaussians(samples, 0.01, progress=3)


def test_simplify_reports_gaussians_removed_per_merge_round(samples):
    cloud = avsplat.fuse_gaussians(samples, 0.01).cloud
    target = len(cloud) // 4
    calls, progress = recorder()
    r = avsplat.simplify(cloud, target_count=target, progress=progress)
    check_reports(calls, len(cloud) - target)
    assert len(calls) == r.iterations + 1  # (0, total), then one per round, the last at total
    same_cloud(r.cloud, avsplat.simplify(cloud, target_count=target).cloud)


def test_simplify_max_error_reports_the_search(samples):
    cloud = avsplat.fuse_gaussians(samples, 0.02).cloud
    cams = avsplat.orbit_cameras(cloud, 2, width=32, height=24)
    calls, progress = recorder()
    r = avsplat.simplify(cloud, max_error=0.02, cameras=cams, progress=progress)
    check_reports(calls, 13)
    assert [d for d, _ in calls][1:r.searches + 1] == list(range(1, r.searches + 1))  # one per simplification tried
    assert r.output_count == avsplat.simplify(cloud, max_error=0.02, cameras=cams).output_count
    with pytest.raises(Stop):
        avsplat.simplify(cloud, max_error=0.02, cameras=cams, progress=stop_at_first_step)


def test_prune_reports_cameras_rendered(samples):
    cloud = avsplat.fuse_gaussians(samples, 0.02).cloud
    cams = avsplat.orbit_cameras(cloud, 3, width=32, height=24)
    calls, progress = recorder()
    r = avsplat.prune(cloud, cams, progress=progress)
    assert calls == [(0, 3), (1, 3), (2, 3), (3, 3)]
    same_cloud(r.cloud, avsplat.prune(cloud, cams).cloud)
    with pytest.raises(Stop):
        avsplat.prune(cloud, cams, progress=stop_at_first_step)


def test_fusion_stream_finish_reports_and_stops(samples):
    def stream():
        s = avsplat.FusionStream(0.01, memory_limit=1 << 20)
        half = len(samples) // 2
        s.add_gaussians(samples[:half])
        s.add_gaussians(samples[half:])
        return s

    calls, progress = recorder()
    r = stream().finish_gaussians(progress=progress)
    check_reports(calls, len(samples))
    same_cloud(r.cloud, stream().finish_gaussians().cloud)
    with pytest.raises(Stop):
        stream().finish(progress=stop_at_first_step)


# The command-line tool.

needs_cli = pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")


def on_terminal(args):
    """(exit code, stdout, what stderr showed) with stderr on a pseudo-terminal."""
    import pty

    master, slave = pty.openpty()
    try:
        p = subprocess.run([BIN, *map(str, args)], stdout=subprocess.PIPE, stderr=slave, timeout=300)
        os.close(slave)
        shown = b""
        while True:
            try:
                chunk = os.read(master, 65536)
            except OSError:
                break
            if not chunk:
                break
            shown += chunk
    finally:
        os.close(master)
    return p.returncode, p.stdout.decode(), shown.decode(errors="replace")


@pytest.fixture(scope="module")
def scene(tmp_path_factory, samples):
    path = tmp_path_factory.mktemp("scene") / "scene.ply"
    avsplat.write_ply(path, avsplat.fuse_gaussians(samples, 0.02).cloud)
    return path


COMMANDS = {
    "render": lambda s, d: ["render", s, "-o", d / "views/", "--orbit", "3", "--size", "32x24"],
    "prune": lambda s, d: ["prune", s, d / "pruned.ply", "--orbit", "3", "--size", "32x24"],
    "simplify": lambda s, d: ["simplify", s, d / "simple.ply", "--ratio", "0.5"],
    "fuse": lambda s, d: ["fuse", s, "-o", d / "fused.ply", "--voxel", "0.05"],
}
BARS = {"render": "rendering views", "prune": "prune: cameras", "simplify": "simplify:", "fuse": "fusing samples"}


@needs_cli
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_cli_bar_on_a_terminal_nothing_with_quiet_or_in_a_pipe(command, scene, tmp_path):
    (tmp_path / "views").mkdir()
    args = COMMANDS[command](scene, tmp_path)
    rc, out, shown = on_terminal(args)
    assert rc == 0, shown
    assert BARS[command] in shown and "\r\033[K" in shown  # drawn, then erased
    for quiet_args in (args + ["--quiet"], args + ["-q"], ["--quiet"] + args):  # global: after or before
        rc, out_quiet, shown = on_terminal(quiet_args)
        assert rc == 0 and shown == "", shown
    piped = subprocess.run([BIN, *map(str, args)], capture_output=True, text=True, timeout=300)
    assert piped.returncode == 0 and piped.stderr == ""
    assert BARS[command] not in piped.stdout
    # The results on stdout are the same with a bar, without one, and in a pipe (but timings,
    # cut from a line at its first time on).
    strip = lambda s: [re.sub(r"[0-9.e+-]+ m?s\b.*", "", line) for line in s.splitlines()]  # noqa: E731
    assert strip(out) == strip(out_quiet) == strip(piped.stdout)
    assert len(strip(out)) >= 2
