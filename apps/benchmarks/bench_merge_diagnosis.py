"""Per-merge diagnosis of simplify's merge cost: does each term order the candidate pairs as the
rendered error of their merges does?

Picks `--pairs` candidate pairs (a random Gaussian and one of its 8 nearest means), merges each
pair alone (the moment match of docs/design/reduction.md, written here in numpy), renders the
scene at `--cameras` orbit cameras and takes the mean squared difference against the unmerged
renders: the rendered error of that one merge. Each term of the cost (G: Runnalls' KL bound, L:
the lost ink, C: the colour difference over every SH band; and, for comparison, F: the squared L2
distance of the amplitude fields the cost once had, and the pair's ink W) is computed for the
same pair, and its Spearman rank correlation with the rendered error printed, over all pairs and
over the visible ones (whose merge changes the renders at all). `--ratio R` first simplifies the
scene to R (so the pairs are those of a later round). Scene: any file avsplat reads (a SOG v1
folder: convert it with splat-transform first).
Usage: PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_merge_diagnosis.py SCENE \\
           [--pairs 300] [--ratio 0.25] [--cameras 3] [--width 200 --height 150]
"""
import argparse

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from scipy.stats import spearmanr

import avsplat

C0 = 0.28209479177387814


def rotations(q):
    w, x, y, z = (q / np.linalg.norm(q, axis=-1, keepdims=True)).T
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                     2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                     2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1).reshape(-1, 3, 3)


def area(s):
    """Knud Thomsen's ellipsoid area (p = 1.6075), as the merge uses."""
    p = 1.6075
    x, y, z = s[..., 0] ** p, s[..., 1] ** p, s[..., 2] ** p
    return 4 * np.pi * ((x * y + x * z + y * z) / 3) ** (1 / p)


def kernel_product(x, y, d):
    s = x + y
    return (2 * np.pi) ** 1.5 * np.sqrt(np.linalg.det(x) * np.linalg.det(y) / np.linalg.det(s)) * \
        np.exp(-0.5 * d @ np.linalg.solve(s, d))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scene")
    ap.add_argument("--pairs", type=int, default=300)
    ap.add_argument("--ratio", type=float, default=None)
    ap.add_argument("--cameras", type=int, default=3)
    ap.add_argument("--width", type=int, default=200)
    ap.add_argument("--height", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    c = avsplat.read_gaussians(args.scene)
    if args.ratio is not None:
        c = avsplat.simplify(c, ratio=args.ratio).cloud
    n = len(c)
    mu = np.asarray(c.means, np.float64)
    s = np.asarray(c.scales, np.float64)
    o = np.asarray(c.opacities, np.float64)
    sh = np.asarray(c.sh, np.float64).reshape(n, -1)
    r = rotations(np.asarray(c.rotations, np.float64))
    cov = np.einsum("nij,nj,nkj->nik", r, s * s, r)
    mass = o * area(s)
    _, nb = cKDTree(mu).query(mu, k=9)
    rng = np.random.default_rng(args.seed)
    first = rng.choice(n, args.pairs, replace=False)
    second = nb[first, 1 + rng.integers(0, 8, args.pairs)]
    cams = avsplat.orbit_cameras(c, args.cameras, width=args.width, height=args.height)
    ref = [avsplat.render(c, cam).color.astype(np.float64) for cam in cams]
    eye = np.eye(3)
    terms = {k: [] for k in ("G", "L", "C", "F", "W", "err")}
    for a, b in zip(first, second):
        w = mass[a] + mass[b]
        pa = mass[a] / w if w > 0 else 0.5
        pb = 1 - pa
        d = mu[a] - mu[b]
        m = cov[a] * pa + cov[b] * pb + pa * pb * np.outer(d, d)
        f = 1e-4 * np.trace(m) / 3
        g = max(0.0, 0.5 * (np.log(np.linalg.det(m + f * eye)) - pa * np.log(np.linalg.det(cov[a] + f * eye))
                            - pb * np.log(np.linalg.det(cov[b] + f * eye))))
        ev, vec = np.linalg.eigh(m)
        sm = np.sqrt(np.maximum(ev, 0))
        am = area(sm[None])[0]
        om = min(1.0, w / am) if am > 0 else max(o[a], o[b])
        lost = max(0.0, 1 - om * am / w) if am > 0 and w > 0 else 0.0
        dsh = sh[a] - sh[b]
        colour = 30 * pa * pb * C0 * C0 * (2 * np.sum(dsh[:3] ** 2) + np.sum(dsh[3:] ** 2))
        ff = 1e-6 * np.trace(m) / 3
        xa, xb, xm = cov[a] + ff * eye, cov[b] + ff * eye, m + ff * eye
        field = (np.pi ** 1.5 * (o[a] ** 2 * np.sqrt(np.linalg.det(xa)) + o[b] ** 2 * np.sqrt(np.linalg.det(xb))
                                 + om ** 2 * np.sqrt(np.linalg.det(xm)))
                 + 2 * (o[a] * o[b] * kernel_product(xa, xb, d) - o[a] * om * kernel_product(xa, xm, pb * d)
                        - o[b] * om * kernel_product(xb, xm, pa * d)))
        if np.linalg.det(vec) < 0:
            vec[:, 0] = -vec[:, 0]
        x, y, z, qw = Rotation.from_matrix(vec).as_quat()
        merged = c.copy()
        merged.means[a] = pa * mu[a] + pb * mu[b]
        merged.scales[a] = sm
        merged.rotations[a] = [qw, x, y, z]
        merged.opacities[a] = om
        merged.sh[a] = (pa * sh[a] + pb * sh[b]).reshape(-1, 3)
        keep = np.ones(n, bool)
        keep[b] = False
        merged = merged.select_mask(keep)
        err = sum(np.mean((avsplat.render(merged, cam).color - rf) ** 2) for cam, rf in zip(cams, ref)) / len(cams)
        for k, v in (("G", g), ("L", lost), ("C", colour), ("F", field), ("W", w), ("err", err)):
            terms[k].append(v)
    t = {k: np.array(v) for k, v in terms.items()}
    err = t["err"]
    visible = err > 1e-12
    print(f"{args.scene}{'' if args.ratio is None else f' simplified to {args.ratio:g}'}: {n:,} Gaussians, "
          f"{args.pairs} pairs, visible {visible.mean():.0%}")
    print(f"{'term':>12s} {'all':>7s} {'visible':>8s}   (Spearman rank correlation with the rendered error)")
    for name, v in (("G + 2L + C", t["G"] + 2 * t["L"] + t["C"]), ("G", t["G"]), ("L", t["L"]), ("C", t["C"]),
                    ("F", t["F"]), ("W", t["W"])):
        print(f"{name:>12s} {spearmanr(v, err).correlation:+7.3f} {spearmanr(v[visible], err[visible]).correlation:+8.3f}")


if __name__ == "__main__":
    main()
