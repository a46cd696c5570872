"""Bit-identity of fuse_voxels and fuse_gaussians across speed work: sha256 digests of
every output array for each policy, recorded with the code before the fusion passes were
restructured, at 1, 2 and 3 OpenMP threads (each count in its own interpreter, as OMP_NUM_THREADS
is read at start-up).

The library's hot loops are built twice (x86-64-v3 and the baseline, common/cpu_dispatch.h),
both without FMA contraction (-ffp-contract=off; the digests were recorded with
the v3 build's contracted double accumulations and did not change, as the sums are rounded to
float). glibc still picks FMA variants of exp and log at run time, so the digests are only
claimed on CPUs with AVX2 and FMA; elsewhere the test is skipped (the float64 reference tests in
test_fusion.py still run there)."""
import hashlib
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import avsplat

# The workload: a sphere shell of samples plus duplicated and clustered ones, so that voxels of
# 1, about 10, and more than 16 samples occur, with tied positions and confidences; 37 feature
# channels (blocks of 16, 4 and single channels in the weighted sums).
SCRIPT = r"""
import hashlib, json, sys
import numpy as np
import avsplat

def workload():
    rng = np.random.default_rng(1818)
    n = 60000
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p = d * rng.uniform(0.99, 1.01, size=(n, 1))
    dense = rng.normal(0.3, 0.004, size=(3000, 3))
    p = np.concatenate([p, dense, p[:2000]]).astype(np.float32)
    f = rng.uniform(-1, 1, size=(len(p), 37)).astype(np.float32)
    f[-1000:] = f[:1000]
    c = rng.standard_normal(len(p)).astype(np.float32)
    c[-500:] = c[:500]
    return p, f, c

def digest(r, fields):
    h = {}
    for name in fields:
        a = getattr(r, name)
        h[name] = hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:16]
    return h

p, f, c = workload()
common = ["voxel_coords", "sample_voxel", "temperature", "variance", "reliability", "entropy", "occupancy", "kept"]
cases = {
    "occupancy": lambda: avsplat.fuse_voxels(p, f, 0.02, c),
    "occupancy_sparsemax": lambda: avsplat.fuse_voxels(p, f, 0.02, c, weights="sparsemax"),
    "occupancy_probability": lambda: avsplat.fuse_voxels(p, f, 0.02, 1 / (1 + np.exp(-c)), confidence_mapping="probability"),
    "occupancy_float64": lambda: avsplat.fuse_voxels(p, f, 0.02, c, precision="float64"),
    "softmax": lambda: avsplat.fuse_voxels(p, f, 0.02, c, policy="softmax"),
    "mean": lambda: avsplat.fuse_voxels(p, f, 0.02, policy="mean"),
    "occupancy_3_channels": lambda: avsplat.fuse_voxels(p, f[:, :3].copy(), 0.02, c),
    "occupancy_no_channels": lambda: avsplat.fuse_voxels(p, f[:, :0].copy(), 0.02, c),
}
out = {}
for name, run in cases.items():
    out[name] = digest(run(), ["positions", "features"] + common)
n = 30000
cloud = avsplat.GaussianCloud(means=p[:n], scales=np.abs(f[:n, :3]) * 0.01 + 0.001, rotations=f[:n, 3:7] + 0.01,
                              opacities=(f[:n, 7] + 1) / 2, sh=f[:n, 8:8 + 27].reshape(n, 9, 3), confidence=c[:n])
r = avsplat.fuse_gaussians(cloud, 0.02)
h = digest(r, ["positions"] + common)
for name in ("means", "scales", "rotations", "opacities", "sh"):
    h["cloud." + name] = hashlib.sha256(np.ascontiguousarray(getattr(r.cloud, name)).tobytes()).hexdigest()[:16]
out["gaussians"] = h
json.dump(out, sys.stdout, sort_keys=True)
"""


def run_digests(threads):
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    done = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def has_v3_fma():
    try:
        with open("/proc/cpuinfo") as fp:
            flags = next((line.split(":", 1)[1].split() for line in fp if line.startswith("flags")), [])
    except OSError:
        return False
    return all(f in flags for f in ("avx2", "fma", "bmi2", "movbe"))


GOLDEN = json.loads(r"""
{
 "gaussians": {
  "cloud.means": "e4e984b315d0be1e",
  "cloud.opacities": "cf97b56666baa41c",
  "cloud.rotations": "84e54a4177efc58d",
  "cloud.scales": "34e2d8c0a306edea",
  "cloud.sh": "84da0dcf8dcdd0c9",
  "entropy": "42a6c97da4b3439c",
  "kept": "e800e454fdb20e93",
  "occupancy": "5c161fdc37cf4932",
  "positions": "e4e984b315d0be1e",
  "reliability": "e5c636eceb6df778",
  "sample_voxel": "255bc5709bdcb0c2",
  "temperature": "56672e17bdc63801",
  "variance": "515b03c0ba1f4895",
  "voxel_coords": "7d33d99de51205f8"
 },
 "mean": {
  "entropy": "521ad9f9b8b9e19e",
  "features": "63f5facdaf148241",
  "kept": "f5d1fa792ee714a4",
  "occupancy": "f5d1fa792ee714a4",
  "positions": "df819365ecf0ff26",
  "reliability": "bf9d6f4942b81479",
  "sample_voxel": "04b63b62b0b1f8cb",
  "temperature": "55d78d4d0fd5cb73",
  "variance": "ab010dc5373ee485",
  "voxel_coords": "f234363716679783"
 },
 "occupancy": {
  "entropy": "027285243991a10b",
  "features": "1b8de3de6bc81f37",
  "kept": "b3b44f20d0791114",
  "occupancy": "f5d1fa792ee714a4",
  "positions": "696eac4d33736b42",
  "reliability": "8c86cb0077a1bd15",
  "sample_voxel": "04b63b62b0b1f8cb",
  "temperature": "225ab19ae7492dcb",
  "variance": "ab010dc5373ee485",
  "voxel_coords": "f234363716679783"
 },
 "occupancy_3_channels": {
  "entropy": "027285243991a10b",
  "features": "9e51d6d18fd4a3a7",
  "kept": "b3b44f20d0791114",
  "occupancy": "f5d1fa792ee714a4",
  "positions": "696eac4d33736b42",
  "reliability": "8c86cb0077a1bd15",
  "sample_voxel": "04b63b62b0b1f8cb",
  "temperature": "225ab19ae7492dcb",
  "variance": "ab010dc5373ee485",
  "voxel_coords": "f234363716679783"
 },
 "occupancy_float64": {
  "entropy": "da22ea814c8dbb4c",
  "features": "8ae68947b24024e5",
  "kept": "b3b44f20d0791114",
  "occupancy": "f5d1fa792ee714a4",
  "positions": "b095a89197b2a4f0",
  "reliability": "08a91cb75a12cf72",
  "sample_voxel": "04b63b62b0b1f8cb",
  "temperature": "b045914b612b0aaf",
  "variance": "ab010dc5373ee485",
  "voxel_coords": "f234363716679783"
 },
 "occupancy_no_channels": {
  "entropy": "027285243991a10b",
  "features": "e3b0c44298fc1c14",
  "kept": "b3b44f20d0791114",
  "occupancy": "f5d1fa792ee714a4",
  "positions": "696eac4d33736b42",
  "reliability": "8c86cb0077a1bd15",
  "sample_voxel": "04b63b62b0b1f8cb",
  "temperature": "225ab19ae7492dcb",
  "variance": "ab010dc5373ee485",
  "voxel_coords": "f234363716679783"
 },
 "occupancy_probability": {
  "entropy": "e3a73c67d0ab8d82",
  "features": "e9169662132326ef",
  "kept": "b3b44f20d0791114",
  "occupancy": "f5d1fa792ee714a4",
  "positions": "7439170f123bd3fc",
  "reliability": "07cd067a255bcf1f",
  "sample_voxel": "04b63b62b0b1f8cb",
  "temperature": "e4bd7be893dfe542",
  "variance": "ab010dc5373ee485",
  "voxel_coords": "f234363716679783"
 },
 "occupancy_sparsemax": {
  "entropy": "daeaf2ac981484d0",
  "features": "5509e6d1abfb6358",
  "kept": "56f7353a608881a5",
  "occupancy": "f5d1fa792ee714a4",
  "positions": "e44ad67056a0166a",
  "reliability": "8c86cb0077a1bd15",
  "sample_voxel": "04b63b62b0b1f8cb",
  "temperature": "225ab19ae7492dcb",
  "variance": "ab010dc5373ee485",
  "voxel_coords": "f234363716679783"
 },
 "softmax": {
  "entropy": "c86146962d3c7d6c",
  "features": "152a8718a5e1ee6b",
  "kept": "f5d1fa792ee714a4",
  "occupancy": "f5d1fa792ee714a4",
  "positions": "b0c3fe51418b2e75",
  "reliability": "8c86cb0077a1bd15",
  "sample_voxel": "04b63b62b0b1f8cb",
  "temperature": "7cee08a6ea6ea340",
  "variance": "ab010dc5373ee485",
  "voxel_coords": "f234363716679783"
 }
}
""")


@pytest.mark.skipif(not has_v3_fma(), reason="digests recorded with the x86-64-v3 (AVX2, FMA) build of the hot loops")
@pytest.mark.parametrize("threads", [1, 2, 3])
def test_outputs_are_bit_identical_to_the_recorded_ones(threads):
    got = run_digests(threads)
    assert sorted(got) == sorted(GOLDEN)
    for case, fields in GOLDEN.items():
        for field, want in fields.items():
            assert got[case][field] == want, f"{case}.{field} differs at {threads} threads"
