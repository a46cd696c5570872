"""select_assist_views, assist_objective and condition_tokens against float64 numpy references of
the definitions in assist_selection.h and condition_tokens.h, written here."""
import itertools
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import avsplat

MASK = (1 << 64) - 1


# ---------------------------------------------------------------- the reference (float64) ----

def rows_of(P, p_sub):
    return np.arange(P) if p_sub >= P else (np.arange(p_sub) * P) // p_sub


def dots(a, b):
    """a @ b.T by elementwise products and sums: equal rows give bit-equal results (BLAS may not)."""
    return (a[:, None, :] * b[None, :, :]).sum(-1)


def statistics(tokens, p_sub):
    X = np.asarray(tokens, np.float32).astype(np.float64)
    u = X.mean(axis=1)
    D = u / np.maximum(np.linalg.norm(u, axis=1), 1e-12)[:, None]
    sigma = np.clip(dots(D, D), -1.0, 1.0)
    xs = X[:, rows_of(X.shape[1], p_sub), :]
    xh = xs / np.maximum(np.linalg.norm(xs, axis=2), 1e-12)[..., None]
    v = xh.var(axis=1).mean(axis=1)
    q = v / v.max() if v.max() > 0 else np.zeros_like(v)
    return D, sigma, xh, q


def mix(z):
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return z ^ (z >> 31)


def draw(seed, s, i):
    return (mix((seed + (2 * s + i + 1) * 0x9E3779B97F4A7C15) & MASK) >> 11) * 2.0 ** -53


def reference_select(tokens, k=4, m=8, p_sub=64, lambda_div=0.3, beta=0.1, jitter=0.0, seed=0):
    """(assists, scores, descriptors, reliability, smallest non-zero score margin)."""
    D, sigma, xh, q = statistics(tokens, p_sub)
    delta = np.maximum(1.0 - sigma, 0.0)
    S = len(D)
    M = max(0, min(m, S - 1))
    K = min(k, M)
    assists = np.zeros((S, K), np.int64)
    scores = np.zeros((S, K))
    margin = np.inf
    for s in range(S):
        pool = sorted((t for t in range(S) if t != s), key=lambda t: (-sigma[s, t], t))[:M]
        if K == 0:
            continue
        sup = {t: dots(xh[s], xh[t]).max(axis=1) for t in pool}
        A = [pool[0]]
        c = sup[pool[0]].copy()
        sc = [0.7 * sigma[s, pool[0]] + np.maximum(0, sup[pool[0]]).mean() + beta * q[pool[0]]]
        last = {}
        while len(A) < K:
            cand = sorted(t for t in pool if t not in A)
            vals = [0.7 * sigma[s, t] + lambda_div * min(delta[t, u] for u in A)
                    + np.maximum(0.0, sup[t] - c).mean() + beta * q[t] for t in cand]
            last = dict(zip(cand, vals))
            best = int(np.argmax(vals))  # the first maximum: the smaller index
            gaps = [vals[best] - v for v in vals if v != vals[best]]
            if gaps:
                margin = min(margin, min(gaps))
            A.append(cand[best])
            sc.append(vals[best])
            c = np.maximum(c, sup[cand[best]])
        rest = sorted(t for t in pool if t not in A)
        if jitter > 0 and rest and draw(seed, s, 0) < jitter:
            t = rest[min(len(rest) - 1, int(draw(seed, s, 1) * len(rest)))]
            A[-1] = t
            sc[-1] = (0.7 * sigma[s, t] + np.maximum(0, sup[t]).mean() + beta * q[t]) if K == 1 else last[t]
        assists[s] = A
        scores[s] = sc
    return assists, scores, D, q, margin


def reference_objective(tokens, s, A, beta, lambda_div, p_sub):
    _, sigma, xh, q = statistics(tokens, p_sub)
    cover = np.max([dots(xh[s], xh[t]).max(axis=1) for t in A], axis=0).mean()
    pairs = [sigma[t, u] for t in A for u in A if t != u]
    return cover + beta * np.mean([q[t] for t in A]) - (lambda_div * np.mean(pairs) if pairs else 0.0)


def reference_condition(tokens, assists, wq, wk, wv, wo, heads, gate=1.0, bq=None, bk=None, bv=None, bo=None):
    f = lambda a: None if a is None else np.asarray(a, np.float32).astype(np.float64)  # noqa: E731
    X, wq, wk, wv, wo = (f(a) for a in (tokens, wq, wk, wv, wo))
    S, P, C = X.shape
    zero = np.zeros(C)
    bq, bk, bv, bo = (zero if b is None else f(b) for b in (bq, bk, bv, bo))
    d = C // heads
    out = X.copy()
    for s in range(S):
        if assists.shape[1] == 0:
            continue
        Q = X[s] @ wq + bq
        Kc = np.concatenate([X[t] @ wk + bk for t in assists[s]])
        Vc = np.concatenate([X[t] @ wv + bv for t in assists[s]])
        O = np.zeros((P, C))
        for h in range(heads):
            sl = slice(h * d, (h + 1) * d)
            L = Q[:, sl] @ Kc[:, sl].T / math.sqrt(d)
            E = np.exp(L - L.max(axis=1, keepdims=True))
            O[:, sl] = (E / E.sum(axis=1, keepdims=True)) @ Vc[:, sl]
        out[s] = X[s] + gate * (O @ wo + bo)
    return out


# ---------------------------------------------------------------- problems ----

def clustered_tokens(S=10, P=40, C=16, seed=0):
    """Views drawn around a few shared directions, so similarities spread out."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(3, C))
    mixes = rng.dirichlet(np.ones(3), size=S)
    base = mixes @ centres
    return (base[:, None, :] + rng.normal(scale=0.8, size=(S, P, C))).astype(np.float32)


def assert_selection_matches(tokens, **kw):
    sel = avsplat.select_assist_views(tokens, **kw)
    A, sc, D, q, margin = reference_select(tokens, **kw)
    assert margin > 1e-5, "the problem has a near tie; the float32 support may legitimately differ"
    np.testing.assert_array_equal(sel.assists, A)
    np.testing.assert_allclose(sel.scores, sc, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(sel.descriptors, D, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(sel.reliability, q, rtol=1e-5, atol=1e-7)
    return sel


# ---------------------------------------------------------------- selection ----

@pytest.mark.parametrize("seed", range(6))
def test_random_problems_match_the_reference(seed):
    tokens = clustered_tokens(S=9 + seed, P=30 + 7 * seed, C=12 + 2 * seed, seed=seed)
    sel = assert_selection_matches(tokens, k=3, m=6, p_sub=16)
    assert sel.assists.dtype == np.int64 and sel.assists.shape == (len(tokens), 3)
    assert sel.scores.dtype == np.float32 and sel.descriptors.dtype == np.float32


@pytest.mark.parametrize("kw", [dict(), dict(k=2, m=3, p_sub=5), dict(k=5, m=5, lambda_div=1.0, beta=0.5),
                                dict(k=1, m=4), dict(p_sub=1000, beta=-0.2, lambda_div=-0.1)])
def test_options_match_the_reference(kw):
    assert_selection_matches(clustered_tokens(S=12, P=50, C=10, seed=7), **kw)


def test_float64_support_matches_the_reference():
    tokens = clustered_tokens(S=11, P=33, C=9, seed=3)
    sel = avsplat.select_assist_views(tokens, k=4, m=7, p_sub=8, precision="float64")
    A, sc, _, _, _ = reference_select(tokens, k=4, m=7, p_sub=8)
    np.testing.assert_array_equal(sel.assists, A)
    np.testing.assert_allclose(sel.scores, sc, rtol=1e-6, atol=1e-6)


def test_exact_ties_go_to_the_smaller_index():
    tokens = clustered_tokens(S=10, P=24, C=8, seed=11)
    tokens[4] = tokens[1]
    tokens[7] = tokens[1]
    tokens[9] = tokens[2]
    sel = avsplat.select_assist_views(tokens, k=4, m=8, p_sub=8)
    A, sc, _, _, _ = reference_select(tokens, k=4, m=8, p_sub=8)
    np.testing.assert_array_equal(sel.assists, A)
    np.testing.assert_allclose(sel.scores, sc, rtol=1e-5, atol=1e-5)
    # A duplicate and its original tie exactly in Sigma: the original (smaller index) comes first
    # wherever both are chosen, and a view's own duplicate is its first assist.
    for s, row in enumerate(sel.assists.tolist()):
        for original, copy in ((1, 4), (1, 7), (2, 9)):
            if copy in row and original in row and s not in (original, copy):
                assert row.index(original) < row.index(copy)
    assert sel.assists[1, 0] == 4 and sel.assists[4, 0] == 1 and sel.assists[7, 0] == 1
    assert sel.assists[2, 0] == 9 and sel.assists[9, 0] == 2


def test_all_views_identical_hand_computed():
    # Every Sigma ties (1), every support ties: pools are the smallest indices, each later pick
    # adds nothing, sees Delta = 0 and the same reliability: assists in index order.
    one = clustered_tokens(S=1, P=20, C=6, seed=2)
    tokens = np.repeat(one, 6, axis=0)
    sel = avsplat.select_assist_views(tokens, k=3, m=4)
    assert sel.assists.tolist() == [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2], [0, 1, 2], [0, 1, 2]]
    np.testing.assert_allclose(sel.reliability, 1.0)
    np.testing.assert_allclose(sel.scores[:, 1:], 0.7 + 0.1, rtol=1e-6)


def test_zero_tokens_hand_computed():
    sel = avsplat.select_assist_views(np.zeros((5, 7, 4), np.float32), k=3)
    assert sel.assists.tolist() == [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2], [0, 1, 2]]
    np.testing.assert_array_equal(sel.descriptors, 0)
    np.testing.assert_array_equal(sel.reliability, 0)
    # First: 0.7 * 0 + 0 + 0.1 * 0; later: Delta = 1 - 0, times lambda_div.
    np.testing.assert_allclose(sel.scores, [[0.0, 0.3, 0.3]] * 5, atol=1e-7)


def test_one_view_and_fewer_views_than_k():
    one = avsplat.select_assist_views(clustered_tokens(S=1))
    assert one.assists.shape == (1, 0) and one.scores.shape == (1, 0)
    assert one.descriptors.shape == (1, 16) and one.reliability.tolist() == [1.0]
    three = assert_selection_matches(clustered_tokens(S=3, seed=4), k=4, m=8)
    assert three.assists.shape == (3, 2)
    for s in range(3):
        assert sorted(three.assists[s].tolist()) == sorted(set(range(3)) - {s})
    empty = avsplat.select_assist_views(np.zeros((0, 5, 3), np.float32))
    assert empty.assists.shape == (0, 0) and empty.descriptors.shape == (0, 3)
    assert avsplat.select_assist_views(clustered_tokens(S=4), k=0).assists.shape == (4, 0)


def test_jitter_is_seeded_and_follows_the_documented_draws():
    tokens = clustered_tokens(S=14, P=30, C=8, seed=5)
    base = avsplat.select_assist_views(tokens, k=3, m=8, p_sub=10)
    for seed in (0, 1, 12345, 2**64 - 1):
        a = avsplat.select_assist_views(tokens, k=3, m=8, p_sub=10, jitter=0.5, seed=seed)
        b = avsplat.select_assist_views(tokens, k=3, m=8, p_sub=10, jitter=0.5, seed=seed)
        np.testing.assert_array_equal(a.assists, b.assists)
        A, sc, _, _, _ = reference_select(tokens, k=3, m=8, p_sub=10, jitter=0.5, seed=seed)
        np.testing.assert_array_equal(a.assists, A)
        np.testing.assert_allclose(a.scores, sc, rtol=1e-5, atol=1e-5)
        changed = (a.assists != base.assists).any(axis=1)
        # Only the last assist may change, and about half of the views do.
        np.testing.assert_array_equal(a.assists[:, :-1], base.assists[:, :-1])
        assert 1 <= changed.sum() <= 13
    always = avsplat.select_assist_views(tokens, k=3, m=8, p_sub=10, jitter=1.0, seed=3)
    assert (always.assists[:, -1] != base.assists[:, -1]).all()
    for s in range(len(tokens)):
        assert len(set(always.assists[s].tolist())) == 3 and s not in always.assists[s]
    # k >= m': nothing to draw from, so jitter changes nothing.
    full = avsplat.select_assist_views(tokens[:4], k=4, jitter=1.0)
    np.testing.assert_array_equal(full.assists, avsplat.select_assist_views(tokens[:4], k=4).assists)


def test_objective_matches_the_reference():
    tokens = clustered_tokens(S=8, P=25, C=7, seed=8)
    for s, A in ((0, [3]), (2, [1, 5]), (7, [0, 1, 2, 6])):
        for beta, lam, p_sub in ((0.1, 0.3, 64), (0.0, 0.0, 6), (0.7, -1.2, 1)):
            got = avsplat.assist_objective(tokens, s, A, beta=beta, lambda_div=lam, p_sub=p_sub)
            assert got == pytest.approx(reference_objective(tokens, s, A, beta, lam, p_sub), rel=1e-12, abs=1e-12)
    assert avsplat.assist_objective(tokens, 1, np.array([0, 2], np.uint8)) == pytest.approx(
        reference_objective(tokens, 1, [0, 2], 0.1, 0.3, 64), rel=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_greedy_coverage_within_1_minus_1_over_e_of_exhaustive(seed):
    # Nonnegative tokens: supports >= 0, so the coverage term is monotone submodular with F({}) = 0.
    rng = np.random.default_rng(100 + seed)
    S, k = 8, 3
    tokens = np.abs(rng.normal(size=(S, 30, 6)) + rng.normal(size=(S, 1, 6))).astype(np.float32)
    sel = avsplat.select_assist_views(tokens, k=k, m=S - 1, p_sub=12, lambda_div=0.0, beta=0.0)
    for s in range(S):
        greedy = avsplat.assist_objective(tokens, s, sel.assists[s], beta=0.0, lambda_div=0.0, p_sub=12)
        best = max(avsplat.assist_objective(tokens, s, list(A), beta=0.0, lambda_div=0.0, p_sub=12)
                   for A in itertools.combinations([t for t in range(S) if t != s], k))
        assert greedy >= (1 - 1 / math.e) * best - 1e-9
        assert greedy <= best + 1e-9


def test_float64_input_is_converted_once_to_float32():
    tokens = clustered_tokens(S=6, seed=9).astype(np.float64) + 1e-9
    a = avsplat.select_assist_views(tokens)
    b = avsplat.select_assist_views(tokens.astype(np.float32))
    np.testing.assert_array_equal(a.assists, b.assists)
    np.testing.assert_array_equal(a.scores, b.scores)


def test_selection_errors_name_the_argument():
    tokens = clustered_tokens(S=5, P=6, C=4)
    bad = tokens.copy()
    bad[3, 2, 1] = np.nan
    bad[4, 0, 0] = np.inf
    with pytest.raises(ValueError, match=r"tokens\[3, 2, 1\] = nan"):
        avsplat.select_assist_views(bad)
    with pytest.raises(ValueError, match=r"tokens\[3, 2, 1\]"):
        avsplat.assist_objective(bad, 0, [1])
    with pytest.raises(ValueError, match=r"tokens: expected shape \(S, P, C\), got \(5, 24\)"):
        avsplat.select_assist_views(tokens.reshape(5, 24))
    with pytest.raises(ValueError, match="tokens: expected at least one token"):
        avsplat.select_assist_views(np.zeros((2, 0, 3), np.float32))
    with pytest.raises(ValueError, match="tokens: expected a float array of real numbers"):
        avsplat.select_assist_views(tokens.astype(np.complex64))
    for kw, word in ((dict(k=-1), "k"), (dict(m=-2), "m"), (dict(p_sub=0), "p_sub"), (dict(jitter=1.5), "jitter"),
                     (dict(jitter=float("nan")), "jitter"), (dict(beta=float("inf")), "beta"),
                     (dict(lambda_div=float("nan")), "lambda_div"), (dict(seed=-1), "seed"),
                     (dict(precision="float16"), "precision")):
        with pytest.raises(ValueError, match=word):
            avsplat.select_assist_views(tokens, **kw)
    for s, A, word in ((5, [1], "s"), (-1, [1], "s"), (0, [], "A"), (0, [5], r"A\[0\] = 5"), (0, [0], r"A\[0\] = 0"),
                       (0, [1, 2, 1], r"A\[2\] = 1: repeated"), (0, [1.5], "A: expected an integer")):
        with pytest.raises(ValueError, match=word):
            avsplat.assist_objective(tokens, s, A)


# ---------------------------------------------------------------- conditioning ----

def weights(C, seed=0, biases=False):
    rng = np.random.default_rng(seed)
    w = [(rng.normal(size=(C, C)) / math.sqrt(C)).astype(np.float32) for _ in range(4)]
    b = [rng.normal(size=C).astype(np.float32) * 0.5 for _ in range(4)] if biases else [None] * 4
    return w, b


@pytest.mark.parametrize("S,P,C,heads,biases,gate", [(5, 40, 16, 4, False, 1.0), (4, 300, 12, 3, True, 0.35),
                                                      (3, 129, 8, 1, True, -2.0), (6, 7, 24, 8, False, 1.0)])
def test_conditioning_matches_the_reference(S, P, C, heads, biases, gate):
    tokens = clustered_tokens(S=S, P=P, C=C, seed=S + P)
    sel = avsplat.select_assist_views(tokens, k=3)
    (wq, wk, wv, wo), (bq, bk, bv, bo) = weights(C, seed=P, biases=biases)
    ref = reference_condition(tokens, sel.assists, wq, wk, wv, wo, heads, gate, bq, bk, bv, bo)
    for precision, tol in (("float32", 1e-5), ("float64", 1e-12)):
        out = avsplat.condition_tokens(tokens, sel.assists, wq, wk, wv, wo, heads, gate=gate, bq=bq, bk=bk, bv=bv,
                                       bo=bo, precision=precision)
        assert out.dtype == np.float32 and out.shape == tokens.shape
        # float64 results are rounded to float32 on output: compare at that resolution.
        np.testing.assert_allclose(out, ref, rtol=0, atol=max(tol, 4e-7 * np.abs(ref).max()))
        if precision == "float32":
            assert np.abs(out - ref).max() <= 1e-5 * max(1.0, np.abs(ref).max())


def test_conditioning_with_peaked_logits_stays_finite():
    # Large logits: without the max subtraction exp overflows.
    tokens = clustered_tokens(S=4, P=20, C=8, seed=1) * 50
    assists = np.array([[1, 2], [0, 3], [3, 1], [2, 0]])
    (wq, wk, wv, wo), _ = weights(8, seed=2)
    out = avsplat.condition_tokens(tokens, assists, wq * 10, wk * 10, wv, wo, 2)
    ref = reference_condition(tokens, assists, wq * 10, wk * 10, wv, wo, 2)
    assert np.isfinite(out).all()
    np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-3)


def test_conditioning_edge_cases():
    tokens = clustered_tokens(S=4, P=10, C=8, seed=3)
    (wq, wk, wv, wo), _ = weights(8)
    # No assists (S = 1, or K = 0): the tokens pass through bit for bit.
    one = avsplat.select_assist_views(tokens[:1])
    np.testing.assert_array_equal(avsplat.condition_tokens(tokens[:1], one.assists, wq, wk, wv, wo, 2), tokens[:1])
    np.testing.assert_array_equal(
        avsplat.condition_tokens(tokens, np.zeros((4, 0), np.int64), wq, wk, wv, wo, 2), tokens)
    # gate 0: the tokens; zero tokens with zero biases: zeros.
    assists = np.array([[1], [2], [3], [0]])
    np.testing.assert_array_equal(avsplat.condition_tokens(tokens, assists, wq, wk, wv, wo, 4, gate=0.0), tokens)
    zeros = np.zeros_like(tokens)
    np.testing.assert_array_equal(avsplat.condition_tokens(zeros, assists, wq, wk, wv, wo, 4), zeros)
    # A repeated assist is the same as attending to it once (the softmax over equal keys).
    once = avsplat.condition_tokens(tokens, assists, wq, wk, wv, wo, 2, precision="float64")
    twice = avsplat.condition_tokens(tokens, np.repeat(assists, 2, axis=1), wq, wk, wv, wo, 2, precision="float64")
    np.testing.assert_allclose(twice, once, rtol=1e-6, atol=1e-6)
    assert avsplat.condition_tokens(np.zeros((0, 3, 8), np.float32), np.zeros((0, 2), np.int64), wq, wk, wv, wo,
                                    2).shape == (0, 3, 8)


def test_conditioning_errors_name_the_argument():
    tokens = clustered_tokens(S=4, P=10, C=8, seed=3)
    (wq, wk, wv, wo), _ = weights(8)
    assists = np.array([[1], [2], [3], [0]])
    bad = tokens.copy()
    bad[2, 9, 7] = np.nan
    with pytest.raises(ValueError, match=r"tokens\[2, 9, 7\] = nan"):
        avsplat.condition_tokens(bad, assists, wq, wk, wv, wo, 2)
    bad_w = wk.copy()
    bad_w[0, 5] = np.inf
    with pytest.raises(ValueError, match=r"wk\[0, 5\] = inf"):
        avsplat.condition_tokens(tokens, assists, wq, bad_w, wv, wo, 2)
    with pytest.raises(ValueError, match=r"bv\[3\] = nan"):
        avsplat.condition_tokens(tokens, assists, wq, wk, wv, wo, 2, bv=np.array([0, 0, 0, np.nan, 0, 0, 0, 0]))
    with pytest.raises(ValueError, match=r"assists\[2, 0\] = 4: out of range"):
        avsplat.condition_tokens(tokens, np.array([[1], [2], [4], [0]]), wq, wk, wv, wo, 2)
    with pytest.raises(ValueError, match=r"assists\[0, 0\] = -1"):
        avsplat.condition_tokens(tokens, np.array([[-1], [2], [3], [0]]), wq, wk, wv, wo, 2)
    with pytest.raises(ValueError, match=r"assists: expected shape \(S, K\), got \(3, 1\)"):
        avsplat.condition_tokens(tokens, assists[:3], wq, wk, wv, wo, 2)
    with pytest.raises(ValueError, match="assists: expected an integer array"):
        avsplat.condition_tokens(tokens, assists.astype(np.float32), wq, wk, wv, wo, 2)
    with pytest.raises(ValueError, match=r"wo: expected shape \(C, C\), got \(8, 7\)"):
        avsplat.condition_tokens(tokens, assists, wq, wk, wv, wo[:, :7], 2)
    with pytest.raises(ValueError, match=r"bq: expected shape \(C\)"):
        avsplat.condition_tokens(tokens, assists, wq, wk, wv, wo, 2, bq=np.zeros(7))
    with pytest.raises(ValueError, match="heads: 3 does not divide the 8 channels"):
        avsplat.condition_tokens(tokens, assists, wq, wk, wv, wo, 3)
    with pytest.raises(ValueError, match="heads"):
        avsplat.condition_tokens(tokens, assists, wq, wk, wv, wo, 0)
    with pytest.raises(ValueError, match="gate"):
        avsplat.condition_tokens(tokens, assists, wq, wk, wv, wo, 2, gate=float("nan"))


# ---------------------------------------------------------------- threads ----

def test_results_do_not_depend_on_the_thread_count(tmp_path):
    tokens = clustered_tokens(S=9, P=200, C=16, seed=12)
    (wq, wk, wv, wo), (bq, bk, bv, bo) = weights(16, biases=True)
    np.savez(tmp_path / "in.npz", tokens=tokens, wq=wq, wk=wk, wv=wv, wo=wo, bq=bq, bk=bk, bv=bv, bo=bo)
    script = f"""
import numpy as np, avsplat
d = np.load({str(tmp_path / 'in.npz')!r})
sel = avsplat.select_assist_views(d["tokens"], k=3, p_sub=40, jitter=0.5, seed=4)
out = avsplat.condition_tokens(d["tokens"], sel.assists, d["wq"], d["wk"], d["wv"], d["wo"], 4,
                               bq=d["bq"], bk=d["bk"], bv=d["bv"], bo=d["bo"])
np.savez({str(tmp_path)!r} + "/out_" + __import__("os").environ["OMP_NUM_THREADS"] + ".npz",
         assists=sel.assists, scores=sel.scores, out=out)
"""
    for threads in ("1", "2", "3"):
        env = dict(os.environ, OMP_NUM_THREADS=threads)
        subprocess.run([sys.executable, "-c", script], check=True, env=env)
    results = [np.load(tmp_path / f"out_{t}.npz") for t in ("1", "2", "3")]
    for r in results[1:]:
        for key in ("assists", "scores", "out"):
            np.testing.assert_array_equal(r[key], results[0][key])
