"""Figures of docs/reliability.md (not a test): Ctrl-C latency of the long stages and peak memory
of hostile files.

Ctrl-C: a child process starts the call, SIGINT is sent `delay` seconds in (inside the stage
named), and the time from the signal to the KeyboardInterrupt reaching Python is printed.
Memory: the peak resident memory (ru_maxrss of the child) reading a 16 KB .sog that declares
2^26 Gaussians in five constant 8192 x 8192 lossless WebPs, and of `avsplat fuse` on a 1 MB .npz
whose 'points' declares 2^28 float32 of a wrong shape.

    PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_reliability.py [ctrl-c|memory]
"""

import io
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
import zipfile

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")

CLOUD = r'''
import sys, time, signal, numpy as np, avsplat
def cloud(n, d, scale=1.0):
    rng = np.random.default_rng(0)
    k = (d + 1) ** 2
    return avsplat.GaussianCloud(rng.normal(size=(n, 3)).astype(np.float32),
                                 (rng.uniform(0.005, 0.03, (n, 3)) * scale).astype(np.float32),
                                 rng.normal(size=(n, 4)).astype(np.float32), rng.uniform(0.2, 1, n).astype(np.float32),
                                 (rng.normal(size=(n, k, 3)) * 0.3).astype(np.float32))
'''
CHILD = CLOUD + r'''
exec(sys.argv[1])
print("ready", flush=True)
try:
    exec(sys.argv[2])
    print("finished", flush=True)
except KeyboardInterrupt:
    print("interrupted %.6f" % time.monotonic(), flush=True)
'''
# name: (setup, call, seconds into the call when SIGINT is sent: inside the stage named)
CTRL_C = {
    "render 1M SH-3 at 1920 x 1080, in the sort and binning stage (5.6 s of 6.3 s)": (
        "c = cloud(1000000, 3, 8.0); cam = avsplat.Camera.look_at(np.array([0, 0, -4.0]), np.zeros(3), "
        "np.array([0, -1, 0.0]), 60, 1920, 1080)", "avsplat.render(c, cam)", 3.0),
    "write_sog 100k SH-3 (palette)": ("c = cloud(100000, 3)", "avsplat.write_sog(sys.argv[3] + '/m.sog', c)", 1.5),
    "write_spz 2M SH-3 (quantising)": ("c = cloud(2000000, 3)", "avsplat.write_spz(sys.argv[3] + '/m.spz', c)", 0.5),
    "write_ply 3M SH-3": ("c = cloud(3000000, 3)", "avsplat.write_ply(sys.argv[3] + '/m.ply', c)", 0.2),
}


def ctrl_c(folder, repeats=2):
    for name, (setup, call, delay) in CTRL_C.items():
        for _ in range(repeats):
            p = subprocess.Popen([sys.executable, "-c", CHILD, setup, call, folder], stdout=subprocess.PIPE, text=True)
            assert p.stdout.readline().strip() == "ready"
            time.sleep(delay)
            sent = time.monotonic()
            p.send_signal(signal.SIGINT)
            out = p.stdout.read().strip()
            p.wait()
            if out.startswith("interrupted"):
                print(f"{name}: KeyboardInterrupt {float(out.split()[1]) - sent:.2f} s after SIGINT", flush=True)
            else:
                print(f"{name}: finished before the SIGINT sent at {delay} s", flush=True)


def peak(args):
    wrapper = ("import resource, subprocess, sys\n"
               "p = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
               "print(p.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss // 1024)\n"
               "sys.stderr.write(p.stderr.strip()[-200:])\n")
    p = subprocess.run([sys.executable, "-c", wrapper, *args], capture_output=True, text=True)
    code, mb = p.stdout.split()
    return f"exit {code}, peak {mb} MB: {p.stderr.strip()}"


def memory(folder):
    from PIL import Image
    src = os.path.join(folder, "src")
    avsplat.write_sog(src, avsplat.GaussianCloud.empty(64, 0))
    with open(os.path.join(src, "meta.json")) as f:
        meta = json.load(f)
    meta["count"] = 1 << 26
    b = io.BytesIO()
    Image.new("RGBA", (8192, 8192), (7, 9, 11, 255)).save(b, "WEBP", lossless=True, method=6)
    names = [*meta["means"]["files"], *meta["scales"]["files"], *meta["quats"]["files"], *meta["sh0"]["files"]]
    bomb = os.path.join(folder, "bomb.sog")
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_STORED) as z:
        z.writestr("meta.json", json.dumps(meta))
        for n in names:
            z.writestr(n, b.getvalue())
    code = "import sys, avsplat\ntry:\n    avsplat.read_sog(sys.argv[1])\nexcept OSError as e:\n    sys.exit(str(e))\n"
    print(f"read_sog of a {os.path.getsize(bomb)}-byte .sog declaring 2^26 Gaussians:",
          peak([sys.executable, "-c", code, bomb]), flush=True)

    header = "{'descr': '<f4', 'fortran_order': False, 'shape': (268435456,), }"
    header = header + " " * (63 - (10 + len(header)) % 64) + "\n"
    npz = os.path.join(folder, "bomb.npz")
    with zipfile.ZipFile(npz, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as z:
        with z.open("points.npy", "w", force_zip64=True) as f:
            f.write(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode())
            zeros = bytes(1 << 24)
            for _ in range((4 << 28) // len(zeros)):
                f.write(zeros)
    print(f"avsplat fuse of a {os.path.getsize(npz)}-byte .npz whose 'points' declares 2^28 float32:",
          peak([BIN, "fuse", npz, "-o", os.path.join(folder, "o.ply"), "--voxel", "0.1"]), flush=True)


def main():
    with open("/proc/cpuinfo") as f:
        cpu = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), platform.machine())
    print(f"{cpu}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    which = sys.argv[1] if len(sys.argv) > 1 else "all"
    with tempfile.TemporaryDirectory() as folder:
        if which in ("all", "ctrl-c"):
            ctrl_c(folder)
        if which in ("all", "memory"):
            memory(folder)


if __name__ == "__main__":
    main()
