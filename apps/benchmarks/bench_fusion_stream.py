"""Benchmark of out-of-core fusion: FusionStream and avsplat.dask against in-memory fuse_voxels (not a test).

Workload: N samples with C float32 channels and a confidence logit, generated chunk by
chunk (chunk i from its own seed, so the input is never held whole by the stream or the Dask
run): 90% uniformly on a unit sphere shell (radius in [0.996, 1.004]) and 10% in a dense ball of
radius 0.05 at the centre (a dense object in a sparse background), voxel 0.01, occupancy policy.

One mode per process, so that the peak RSS (getrusage ru_maxrss) is that mode's:
  memory   all chunks concatenated, then avsplat.fuse_voxels (the in-memory operator)
  stream   avsplat.FusionStream(voxel, memory_limit=...) fed chunk by chunk, then finish()
  dask     avsplat.dask.fuse_voxels on a LocalCluster of --workers processes with --worker-memory
           each; the chunks are generated inside the workers (dask.delayed), the fused arrays
           are computed back to the client; peak RSS is reported for the client and each worker

Time is wall-clock from the first chunk generated to the fused result in memory (generation
included in every mode, since the stream and Dask consume the chunks as they are generated);
--gen-only times the generation alone, to subtract.

  PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_fusion_stream.py --mode stream \\
      --samples 10000000 --channels 8 --memory-limit 2G
"""
import argparse
import resource
import time

import numpy as np

import avsplat
from avsplat.eval._report import machine


def parse_bytes(text):
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
    return int(float(text[:-1]) * units[text[-1]]) if text[-1] in units else int(text)


def chunk(i, rows, channels, seed=0):
    rng = np.random.default_rng([seed, i])
    d = rng.standard_normal((rows, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = rng.uniform(0.996, 1.004, size=(rows, 1))
    dense = rng.random(rows) < 0.1
    r[dense, 0] = 0.05 * rng.random(dense.sum()) ** (1 / 3)
    positions = (d * r).astype(np.float32)
    features = rng.uniform(-1, 1, size=(rows, channels)).astype(np.float32)
    confidence = rng.standard_normal(rows).astype(np.float32)
    return positions, features, confidence


def chunk_sizes(n, rows):
    return [min(rows, n - s) for s in range(0, n, rows)]


def peak_rss_mib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mode", choices=["memory", "stream", "dask", "gen-only"], required=True)
    ap.add_argument("--samples", type=int, default=10_000_000)
    ap.add_argument("--channels", type=int, default=8)
    ap.add_argument("--chunk", type=int, default=1_000_000, help="samples per generated chunk")
    ap.add_argument("--voxel", type=float, default=0.01)
    ap.add_argument("--memory-limit", default="2G", help="FusionStream memory_limit")
    ap.add_argument("--work-dir", default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--worker-memory", default="3G")
    ap.add_argument("--blocks", type=int, default=None, help="Dask blocks (default: from the input size)")
    args = ap.parse_args()
    n, c = args.samples, args.channels
    sizes = chunk_sizes(n, args.chunk)
    in_bytes = n * (4 * (3 + c + 1))
    print(f"mode {args.mode}: {n:,} samples x {c} channels ({in_bytes / 2**30:.2f} GiB of input) in {len(sizes)} "
          f"chunks, voxel {args.voxel}")
    print(f"machine: {machine()}")
    t0 = time.perf_counter()
    if args.mode == "gen-only":
        for i, rows in enumerate(sizes):
            chunk(i, rows, c)
        voxels = 0
    elif args.mode == "memory":
        parts = [chunk(i, rows, c) for i, rows in enumerate(sizes)]
        p, f, conf = (np.concatenate([x[k] for x in parts]) for k in range(3))
        del parts
        voxels = len(avsplat.fuse_voxels(p, f, args.voxel, conf))
    elif args.mode == "stream":
        s = avsplat.FusionStream(args.voxel, memory_limit=parse_bytes(args.memory_limit), work_dir=args.work_dir)
        for i, rows in enumerate(sizes):
            s.add(*chunk(i, rows, c))
        t_add = time.perf_counter() - t0
        voxels = len(s.finish())
        print(f"  added (generated, partitioned, spilled) in {t_add:.2f} s: {s.num_blocks} blocks, "
              f"{s.spilled_bytes / 2**30:.2f} GiB spilled")
    else:
        import dask
        import dask.array as da
        import distributed

        import avsplat.dask as ad

        cluster = distributed.LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                                           memory_limit=parse_bytes(args.worker_memory), dashboard_address=":0")
        client = distributed.Client(cluster)
        t0 = time.perf_counter()
        gen = [dask.delayed(chunk, nout=3, pure=True)(i, rows, c) for i, rows in enumerate(sizes)]
        p = da.concatenate([da.from_delayed(g[0], shape=(rows, 3), dtype=np.float32) for g, rows in zip(gen, sizes)])
        f = da.concatenate([da.from_delayed(g[1], shape=(rows, c), dtype=np.float32) for g, rows in zip(gen, sizes)])
        conf = da.concatenate([da.from_delayed(g[2], shape=(rows,), dtype=np.float32) for g, rows in zip(gen, sizes)])
        r = ad.fuse_voxels(p, f, args.voxel, conf, blocks=args.blocks)
        got = r.compute()
        voxels = len(got.voxel_coords)
        rss = client.run(peak_rss_mib)
        print(f"  blocks {len(got.block_samples)}: samples per block min {got.block_samples.min():,}, max "
              f"{got.block_samples.max():,} (max / mean {got.block_samples.max() / got.block_samples.mean():.2f})")
        print("  peak RSS per worker (MiB): " + ", ".join(f"{v:.0f}" for v in rss.values()))
    seconds = time.perf_counter() - t0
    print(f"  {voxels:,} voxels in {seconds:.2f} s: {n / seconds / 1e6:.2f} M samples/s; "
          f"peak RSS of this process {peak_rss_mib():.0f} MiB")


if __name__ == "__main__":
    main()
