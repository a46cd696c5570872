"""select_views_by_coverage against a plain (not lazy) greedy written here in numpy, float64."""
import itertools
import math

import numpy as np
import pytest

import avsplat


def voxel_keys(points, voxel):
    """The fusion voxel rule: round(p / voxel) per axis, halves away from zero."""
    q = points.astype(np.float64) / voxel
    return np.sign(q) * np.floor(np.abs(q) + 0.5)


def view_sets(points, voxel, keep=None):
    """The set of voxel keys of each view (points (S, ..., 3); keep (S, ...) bool or None)."""
    sets = []
    for s in range(points.shape[0]):
        p = points[s].reshape(-1, 3)
        if keep is not None:
            p = p[keep[s].reshape(-1)]
        sets.append({tuple(k) for k in voxel_keys(p, voxel)})
    return sets


def plain_greedy(sets, budget=None, min_gain=0.0):
    """Greedy coverage, every gain recomputed at every step; ties to the smaller index."""
    total = len(set().union(*sets)) if sets else 0
    covered, order, gains, coverage = set(), [], [], []
    left = list(range(len(sets)))
    budget = len(sets) if budget is None else budget
    while left and len(order) < budget:
        g = [len(sets[t] - covered) for t in left]
        best = max(range(len(left)), key=lambda i: (g[i], -left[i]))
        if g[best] < min_gain * total or (g[best] == 0 and min_gain > 0):
            break
        covered |= sets[left[best]]
        order.append(left[best])
        gains.append(g[best])
        coverage.append(len(covered))
        left.pop(best)
    return order, gains, coverage, total


def random_views(seed, views=9, h=12, w=10):
    """Views that see overlapping patches of a plane and a box: coverage overlaps a lot."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-1, 1, (views, 3))
    spread = rng.uniform(0.1, 0.8, views)
    pts = centres[:, None, None, :] + rng.normal(size=(views, h, w, 3)) * spread[:, None, None, None]
    return pts.astype(np.float32)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("budget,min_gain", [(None, 0.0), (3, 0.0), (None, 0.05), (1, 0.0)])
def test_order_gains_and_coverage_equal_plain_greedy(seed, budget, min_gain):
    pts = random_views(seed)
    voxel = 0.25
    r = avsplat.select_views_by_coverage(pts, voxel, budget=budget, min_gain=min_gain)
    order, gains, coverage, total = plain_greedy(view_sets(pts, voxel), budget, min_gain)
    assert r.order.tolist() == order
    assert r.gains.tolist() == gains
    assert r.coverage.tolist() == coverage
    assert r.total_voxels == total
    assert r.points_used == pts.shape[0] * pts.shape[1] * pts.shape[2]
    assert r.order.dtype == np.int64
    if budget is None and min_gain == 0:
        assert sorted(order) == list(range(pts.shape[0])) and coverage[-1] == total


def test_duplicate_views_tie_to_the_smaller_index_and_add_nothing():
    base = random_views(3, views=4)
    pts = np.concatenate([base, base[[2, 0]]])  # views 4 and 5 repeat views 2 and 0
    r = avsplat.select_views_by_coverage(pts, 0.3)
    order, gains, _, _ = plain_greedy(view_sets(pts, 0.3))
    assert r.order.tolist() == order
    # Each duplicate comes after its original, and the later copy adds no voxel.
    assert order.index(2) < order.index(4) and order.index(0) < order.index(5)
    assert r.gains[order.index(4)] == 0 and r.gains[order.index(5)] == 0
    # With a minimum gain, the duplicates are left out.
    r = avsplat.select_views_by_coverage(pts, 0.3, min_gain=1e-9)
    assert 4 not in r.order.tolist() and 5 not in r.order.tolist()


def test_hand_computed_case():
    # Voxel 1: view 0 covers voxels {0, 1, 2} on x, view 1 {2, 3}, view 2 {4}, view 3 {0, 1}.
    xs = [[0, 1, 2], [2, 3, 3], [4, 4, 4], [0, 1, 1]]
    pts = np.zeros((4, 3, 3), np.float32)
    pts[:, :, 0] = xs
    r = avsplat.select_views_by_coverage(pts, 1.0)
    # View 0 adds 3; then views 1 ({3}) and 2 ({4}) add 1 each: the smaller index first; view 3 adds 0.
    assert r.order.tolist() == [0, 1, 2, 3]
    assert r.gains.tolist() == [3, 1, 1, 0]
    assert r.coverage.tolist() == [3, 4, 5, 5]
    assert r.total_voxels == 5
    assert repr(r) == "ViewCoverage(views=4, covered=5 of 5 voxels)"


def test_confidence_and_valid_leave_pixels_out():
    pts = random_views(7, views=6)
    rng = np.random.default_rng(1)
    conf = rng.normal(size=pts.shape[:3]).astype(np.float32)
    valid = rng.uniform(size=pts.shape[:3]) < 0.8
    pts[~valid] = np.nan  # invalid pixels are not read
    r = avsplat.select_views_by_coverage(pts, 0.2, confidence=conf, min_confidence=0.3, valid=valid)
    keep = valid & (conf > 0.3)
    order, gains, coverage, total = plain_greedy(view_sets(pts, 0.2, keep))
    assert (r.order.tolist(), r.gains.tolist(), r.coverage.tolist(), r.total_voxels) == (order, gains, coverage,
                                                                                          total)
    assert r.points_used == int(keep.sum())


def test_points_per_view_layout_and_pixel_order_do_not_matter():
    pts = random_views(11, views=5)
    flat = pts.reshape(5, -1, 3)
    a = avsplat.select_views_by_coverage(pts, 0.2)
    perm = np.random.default_rng(0).permutation(flat.shape[1])
    b = avsplat.select_views_by_coverage(flat[:, perm], 0.2)
    c = avsplat.select_views_by_coverage(pts.astype(np.float64), 0.2)
    for r in (b, c):
        assert r.order.tolist() == a.order.tolist() and r.coverage.tolist() == a.coverage.tolist()


@pytest.mark.parametrize("seed", range(4))
def test_greedy_covers_at_least_1_minus_1_over_e_of_the_best_set(seed):
    pts = random_views(20 + seed, views=8, h=6, w=6)
    sets = view_sets(pts, 0.3)
    for k in (2, 3):
        r = avsplat.select_views_by_coverage(pts, 0.3, budget=k)
        best = max(len(set().union(*(sets[i] for i in combo))) for combo in itertools.combinations(range(8), k))
        assert r.coverage[-1] >= (1 - 1 / math.e) * best
        assert r.coverage[-1] <= best


def test_edge_cases():
    one = random_views(0, views=1)
    r = avsplat.select_views_by_coverage(one, 0.5)
    assert r.order.tolist() == [0] and r.coverage[0] == r.total_voxels
    empty = avsplat.select_views_by_coverage(np.zeros((0, 4, 4, 3), np.float32), 0.5)
    assert empty.order.size == 0 and empty.total_voxels == 0
    # All points in one voxel: the first view covers everything.
    same = np.zeros((3, 2, 2, 3), np.float32)
    r = avsplat.select_views_by_coverage(same, 1e-6)
    assert r.order.tolist() == [0, 1, 2] and r.gains.tolist() == [1, 0, 0]
    # Nothing valid: every gain is 0.
    r = avsplat.select_views_by_coverage(same, 1.0, valid=np.zeros((3, 2, 2), bool))
    assert r.total_voxels == 0 and r.gains.tolist() == [0, 0, 0] and r.points_used == 0


def test_errors_name_the_argument_and_index():
    pts = random_views(0, views=3, h=4, w=5)
    bad = pts.copy()
    bad[1, 2, 3, 1] = np.nan
    with pytest.raises(ValueError, match=r"points\[1, 2, 3, 1\] = nan"):
        avsplat.select_views_by_coverage(bad, 0.1)
    conf = np.ones(pts.shape[:3], np.float32)
    conf[2, 0, 1] = np.inf
    with pytest.raises(ValueError, match=r"confidence\[2, 0, 1\] = inf"):
        avsplat.select_views_by_coverage(pts, 0.1, confidence=conf)
    with pytest.raises(ValueError, match="voxel_size"):
        avsplat.select_views_by_coverage(pts, 0.0)
    with pytest.raises(ValueError, match="budget"):
        avsplat.select_views_by_coverage(pts, 0.1, budget=0)
    with pytest.raises(ValueError, match="min_gain"):
        avsplat.select_views_by_coverage(pts, 0.1, min_gain=1.5)
    with pytest.raises(ValueError, match=r"points: expected shape"):
        avsplat.select_views_by_coverage(pts[0, 0], 0.1)
    with pytest.raises(ValueError, match=r"confidence: expected shape \(S, H, W\)"):
        avsplat.select_views_by_coverage(pts, 0.1, confidence=conf[:2])
    with pytest.raises(ValueError, match="does not fit int32"):
        avsplat.select_views_by_coverage(pts * 1e8, 1e-3)
