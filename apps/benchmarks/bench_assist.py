"""Assist-View selection and conditioning: avsplat against the same algorithm in PyTorch (CPU).

    OMP_WAIT_POLICY=passive PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_assist.py \
        --views 16,64,256 --conditioning-views 16

Workload: S views of P = 1369 tokens (37 x 37 patches) of C = 1024 float32 channels,
k = 4 assists from a pool of m = 8, p_sub = 64 subsampled rows; conditioning with 16 heads and
random C x C weights. Every measurement runs in a fresh subprocess that builds the tokens, so its
peak memory (the peak resident size, reset before the calls, minus the resident size then: inputs excluded) is its own.
Both sides get the same number of threads (avsplat: OpenMP; PyTorch: torch.set_num_threads, and
OPENBLAS_NUM_THREADS when an OpenBLAS is given).

PyTorch is a peer for this benchmark only (Debian's python3-torch); it is not a dependency of
avsplat, and the peer is skipped when torch is missing. Debian's torch calls the system
libblas.so.3 for its matrix products; `--openblas DIR` runs a second PyTorch peer with DIR (a
folder holding an OpenBLAS libblas.so.3, e.g. unpacked from Debian's libopenblas0-pthread) first
on LD_LIBRARY_PATH.

Printed: the machine (lscpu), threads, load average before and after, median seconds over
--repeats, peak memory, and torch / avsplat ratios measured in the same run; with --markdown, a
table for docs/benchmarks/assist.md.
"""
import argparse
import json
import os
import platform
import subprocess
import sys
import time

CHILD = r"""
import json, math, os, statistics, sys, time
import numpy as np
cfg = json.loads(sys.argv[1])
S, P, C = cfg["S"], cfg["P"], cfg["C"]

def status(field):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024


def reset_peak():
    # Linux: writing 5 to clear_refs resets the peak resident size (VmHWM) to the current one.
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")

rng = np.random.default_rng(0)
# Views around a few shared directions (as tokens of overlapping views are), plus noise.
centres = rng.standard_normal((8, C), dtype=np.float32)
tokens = np.empty((S, P, C), np.float32)
for s in range(S):
    w = rng.dirichlet(np.ones(8)).astype(np.float32)
    tokens[s] = w @ centres + rng.standard_normal((P, C), dtype=np.float32)
ws = [(rng.standard_normal((C, C), dtype=np.float32) / np.float32(math.sqrt(C))) for _ in range(4)]
bs = [rng.standard_normal(C, dtype=np.float32) * np.float32(0.1) for _ in range(4)]
k, m, p_sub, heads = cfg["k"], cfg["m"], cfg["p_sub"], cfg["heads"]
assists = None
if cfg["op"] == "conditioning":
    assists = np.stack([(np.arange(1, k + 1) + s) % S for s in range(S)]).astype(np.int64)

if cfg["impl"] == "avsplat":
    import avsplat
    def select():
        return avsplat.select_assist_views(tokens, k=k, m=m, p_sub=p_sub).assists
    def condition():
        return avsplat.condition_tokens(tokens, assists, *ws, heads, gate=1.0, bq=bs[0], bk=bs[1], bv=bs[2], bo=bs[3])
else:
    import torch
    torch.set_num_threads(cfg["threads"])
    X = torch.from_numpy(tokens)
    W = [torch.from_numpy(w) for w in ws]
    B = [torch.from_numpy(b) for b in bs]

    @torch.no_grad()
    def select():
        # The same algorithm as avsplat.select_assist_views, batched over views.
        n = X.shape[0]
        u = X.mean(dim=1, dtype=torch.float64)
        D = u / u.norm(dim=1, keepdim=True).clamp_min(1e-12)
        sigma = (D @ D.T).clamp(-1, 1)
        delta = (1 - sigma).clamp_min(0)
        rows = torch.arange(P) if p_sub >= P else torch.div(torch.arange(p_sub) * P, p_sub, rounding_mode="floor")
        xs = X[:, rows]
        xh = xs / xs.norm(dim=2, keepdim=True).clamp_min(1e-12)
        v = xh.double().var(dim=1, unbiased=False).mean(dim=1)
        q = v / v.max() if v.max() > 0 else torch.zeros_like(v)
        M = max(0, min(m, n - 1))
        K = min(k, M)
        key = sigma.clone()
        key.fill_diagonal_(-math.inf)
        pool = torch.sort(-key, dim=1, stable=True).indices[:, :M]          # ties: smaller index
        # Candidates in index order (for the tie rule); the first assist is pool[:, 0].
        cand = torch.sort(pool, dim=1).values
        sup = torch.matmul(xh[:, None], xh[cand].transpose(-1, -2)).amax(-1).double()  # S, M, R
        sig = torch.gather(sigma, 1, cand)
        qc = q[cand]
        first = (cand == pool[:, :1]).double().argmax(dim=1)
        ar = torch.arange(n)
        taken = torch.zeros(n, M, dtype=torch.bool)
        taken[ar, first] = True
        c = sup[ar, first]
        dd = delta[cand[:, :, None], cand[:, None, :]]                     # S, M, M
        min_delta = dd[ar, :, first]
        chosen = [cand[ar, first]]
        for _ in range(1, K):
            score = 0.7 * sig + cfg["lambda_div"] * min_delta + (sup - c[:, None]).clamp_min(0).mean(-1) \
                + cfg["beta"] * qc
            score[taken] = -math.inf
            best = score.argmax(dim=1)                                       # first maximum
            taken[ar, best] = True
            c = torch.maximum(c, sup[ar, best])
            min_delta = torch.minimum(min_delta, dd[ar, :, best])
            chosen.append(cand[ar, best])
        return torch.stack(chosen, dim=1).numpy() if K else np.zeros((n, 0), np.int64)

    @torch.no_grad()
    def condition():
        n, _, c_ = X.shape
        d = c_ // heads
        idx = torch.from_numpy(assists)
        keys = X @ W[1] + B[1]
        values = X @ W[2] + B[2]
        out = torch.empty_like(X)
        for s in range(n):
            q_ = (X[s] @ W[0] + B[0]).view(P, heads, d).transpose(0, 1)          # H, P, d
            kc = keys[idx[s]].reshape(-1, heads, d).transpose(0, 1)                # H, K P, d
            vc = values[idx[s]].reshape(-1, heads, d).transpose(0, 1)
            att = torch.softmax(q_ @ kc.transpose(1, 2) / math.sqrt(d), dim=-1)    # max-subtracted
            o = (att @ vc).transpose(0, 1).reshape(P, c_)
            out[s] = X[s] + (o @ W[3] + B[3])
        return out.numpy()

fn = select if cfg["op"] == "selection" else condition
reset_peak()
before = status("VmRSS")
times = []
result = None
for _ in range(cfg["repeats"]):
    t = time.perf_counter()
    result = fn()
    times.append(time.perf_counter() - t)
peak = status("VmHWM")
out = {"seconds": statistics.median(times), "all": times, "peak_extra_mib": (peak - before) / 2**20,
       "input_mib": tokens.nbytes / 2**20}
if cfg["op"] == "selection":
    out["assists"] = np.asarray(result).tolist()
else:
    out["checksum"] = float(np.asarray(result, np.float64).sum())
    out["sample"] = np.asarray(result)[:, :4, :4].astype(np.float64).ravel().tolist()
print("RESULT " + json.dumps(out))
"""


def machine():
    model = "unknown"
    try:
        for line in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines():
            if line.startswith("Model name:"):
                model = line.split(":", 1)[1].strip()
    except OSError:
        pass
    return model


def run(cfg, env_extra=None):
    env = dict(os.environ)
    env["OMP_NUM_THREADS"] = str(cfg["threads"])
    env.setdefault("OMP_WAIT_POLICY", "passive")
    env.update(env_extra or {})
    p = subprocess.run([sys.executable, "-c", CHILD, json.dumps(cfg)], capture_output=True, text=True, env=env)
    for line in p.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"{cfg['impl']} {cfg['op']} S={cfg['S']} failed:\n{p.stderr[-3000:]}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", default="16,64,256", help="S for selection")
    ap.add_argument("--conditioning-views", default="16,64,256", help="S for conditioning ('' for none)")
    ap.add_argument("--tokens", type=int, default=1369)
    ap.add_argument("--channels", type=int, default=1024)
    ap.add_argument("--heads", type=int, default=16)
    ap.add_argument("--k", type=int, default=4)
    ap.add_argument("--m", type=int, default=8)
    ap.add_argument("--p-sub", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=int(os.environ.get("OMP_NUM_THREADS", os.cpu_count() or 1)))
    ap.add_argument("--openblas", default="", help="folder with an OpenBLAS libblas.so.3 for a second torch peer")
    ap.add_argument("--peers", default="torch,torch+openblas", help="which PyTorch peers to run")
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()

    try:
        import torch  # noqa: F401
        peers = [("torch", {})]
        if args.openblas:
            peers.append(("torch+openblas", {"LD_LIBRARY_PATH": args.openblas,
                                             "OPENBLAS_NUM_THREADS": str(args.threads)}))
        wanted = set(args.peers.split(","))
        peers = [(n, e) for n, e in peers if n in wanted]
    except ImportError:
        print("PyTorch not installed: the peer is skipped")
        peers = []

    load0 = os.getloadavg()
    print(f"machine: {machine()}, {os.cpu_count()} logical CPUs, {platform.machine()}; threads {args.threads}; "
          f"load average {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f} at start (shared machine)")
    rows = []
    plan = [("selection", int(s)) for s in args.views.split(",") if s] + \
           [("conditioning", int(s)) for s in args.conditioning_views.split(",") if s]
    for op, S in plan:
        base = dict(op=op, S=S, P=args.tokens, C=args.channels, k=args.k, m=args.m, p_sub=args.p_sub,
                    heads=args.heads, lambda_div=0.3, beta=0.1, repeats=args.repeats, threads=args.threads)
        ours = run(dict(base, impl="avsplat"))
        line = {"op": op, "S": S, "avsplat": ours, "peers": {}}
        print(f"{op:12s} S={S:4d} avsplat {ours['seconds']:9.3f} s  peak +{ours['peak_extra_mib']:8.0f} MiB  "
              f"(input {ours['input_mib']:.0f} MiB) runs {['%.3f' % t for t in ours['all']]}", flush=True)
        for name, env in peers:
            theirs = run(dict(base, impl="torch", repeats=max(1, args.repeats if op == "selection" else 1)), env)
            same = (theirs.get("assists") == ours.get("assists")) if op == "selection" else \
                abs(theirs["checksum"] - ours["checksum"]) <= 1e-4 * max(1.0, abs(ours["checksum"])) and \
                max(abs(a - b) for a, b in zip(theirs["sample"], ours["sample"])) < 1e-3
            line["peers"][name] = dict(theirs, agrees=same)
            print(f"{'':12s} {'':6s} {name:14s} {theirs['seconds']:9.3f} s  peak +{theirs['peak_extra_mib']:8.0f} MiB  "
                  f"ratio {theirs['seconds'] / ours['seconds']:6.2f}x  same result: {same}", flush=True)
        rows.append(line)
    load1 = os.getloadavg()
    print(f"load average {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f} at the end; "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    if args.markdown:
        names = [n for n, _ in peers]
        head = "| operation | S | avsplat s | avsplat peak MiB | " + " | ".join(
            f"{n} s | {n} peak MiB | {n} / avsplat" for n in names) + " |"
        print(head)
        print("|" + "---|" * (4 + 3 * len(names)))
        for r in rows:
            cells = [r["op"], str(r["S"]), f"{r['avsplat']['seconds']:.3f}", f"{r['avsplat']['peak_extra_mib']:.0f}"]
            for n in names:
                p = r["peers"][n]
                cells += [f"{p['seconds']:.3f}", f"{p['peak_extra_mib']:.0f}", f"{p['seconds'] / r['avsplat']['seconds']:.2f}"]
            print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
