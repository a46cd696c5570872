"""The simulator's error models: each one's statistics against what its parameters
promise, its independence from the others, and determinism across thread counts."""

import math
import os
import subprocess
import sys

import numpy as np
import pytest

import avsplat

if not hasattr(avsplat, "simulate_predictions"):
    pytest.skip("avsplat built without the simulator", allow_module_level=True)

SMALL = dict(views=4, width=48, height=36, target_views=1)
C0 = 0.28209479177387814


def _phi(x):
    return 0.5 * (1.0 + np.vectorize(math.erf)(x / math.sqrt(2.0)))


def _true_depth(p):
    """(S, H, W) camera-space depth of the true hits in the true cameras (0 where invalid)."""
    depth = np.zeros(p.valid.shape)
    for s, cam in enumerate(p.true_cameras):
        pts = p.true_points[s].reshape(-1, 3).astype(np.float64)
        z = pts @ cam.world_to_camera[2, :3] + cam.world_to_camera[2, 3]
        depth[s] = np.where(p.valid[s], z.reshape(p.height, p.width), 0.0)
    return depth


def _spearman(a, b):
    def ranks(x):
        order = np.argsort(x, kind="stable")
        r = np.empty(len(x))
        r[order] = np.arange(len(x))
        # mean ranks for ties
        _, inv, counts = np.unique(x, return_inverse=True, return_counts=True)
        sums = np.bincount(inv, weights=r)
        return (sums / counts)[inv]
    return float(np.corrcoef(ranks(a), ranks(b))[0, 1])


def test_every_model_off_by_default_and_independent_of_the_others():
    base = avsplat.simulate_predictions(seed=3, **SMALL)
    # Zero strengths are the defaults.
    zero = avsplat.simulate_predictions(seed=3, footprint_sigma=0, exposure_sigma=0, white_balance_sigma=0,
                                        specular=0, mixed_pixel_radius=0, attribute_noise=0, **SMALL)
    for name in ("points", "colors", "confidence", "features", "uncertainty"):
        np.testing.assert_array_equal(getattr(base, name), getattr(zero, name), err_msg=name)
    # Without attribute noise the features are the encoded per-pixel Gaussians, the opacity logit
    # the confidence.
    v = base.valid
    f = base.features[v]
    np.testing.assert_array_equal(f[:, 0], base.confidence[v])
    clean = avsplat.encode_gaussians(base.gaussians())
    np.testing.assert_allclose(f[:, 1:], clean[:, 1:], atol=1e-6)
    # Each model leaves the other models' numbers alone (each has its own random stream).
    noisy = avsplat.simulate_predictions(seed=3, attribute_noise=0.05, exposure_sigma=0.3, mixed_pixel_radius=2,
                                         **SMALL)
    for name in ("points", "confidence", "true_error", "normals", "valid"):
        np.testing.assert_array_equal(getattr(base, name), getattr(noisy, name), err_msg=name)
    assert not np.array_equal(base.colors, noisy.colors)
    assert not np.array_equal(base.features, noisy.features)


def test_footprint_matches_a_brute_force_area_integral():
    """ground_truth with footprint_sigma is the footprint-weighted mean of a fine grid of rays:
    cast the fine grid as one big camera (supersample 1), weight it in numpy, compare."""
    ss, sigma = 3, 0.7
    cam = avsplat.target_cameras(views=8, width=40, height=30, target_views=1)[0]
    margin = math.ceil(4 * sigma)
    fine = avsplat.Camera(cam.fx * ss, cam.fy * ss, (cam.cx + margin) * ss, (cam.cy + margin) * ss,
                          (cam.width + 2 * margin) * ss, (cam.height + 2 * margin) * ss, cam.world_to_camera,
                          cam.near, cam.far)
    samples = avsplat.ground_truth(fine, supersample=1).color.astype(np.float64)
    taps = ss * (1 + 2 * margin)
    d = (np.arange(taps) - margin * ss + 0.5) / ss - 0.5  # sample offsets from the pixel centre
    w = _phi((d + 0.5) / sigma) - _phi((d - 0.5) / sigma)
    ref = np.zeros((cam.height, cam.width, 3))
    for y in range(cam.height):
        for x in range(cam.width):
            block = samples[y * ss:y * ss + taps, x * ss:x * ss + taps]
            ref[y, x] = np.einsum("i,j,ijc->c", w, w, block) / w.sum() ** 2
    got = avsplat.ground_truth(cam, supersample=ss, footprint_sigma=sigma).color
    # The same rays up to the rounding of their directions (a sample on a silhouette may flip).
    assert np.abs(got - ref).mean() < 2e-4
    assert np.quantile(np.abs(got - ref), 0.99) < 2e-3
    # And the blur is there: it differs clearly from the box footprint.
    box = avsplat.ground_truth(cam, supersample=ss).color
    assert np.abs(box - ref).mean() > 10 * np.abs(got - ref).mean()


@pytest.mark.parametrize("sigma", [0.0, 0.5, 1.0])
def test_edge_spread_has_the_footprint_variance(sigma):
    """Across a straight edge (the wall's top against the empty sky) the alpha profile's derivative
    is the footprint's line spread convolved with one pixel and sampled at the pixels. Averaged over
    the edge's sub-pixel phase (the camera is rolled so that the edge crosses one pixel over the
    image's width), its variance is 1/12 (pixel box) + sigma^2 (blur) + 1/12 (differencing), pixels^2."""
    W, H = 64, 40
    roll = math.atan(1.0 / W)
    cam = avsplat.Camera.look_at([0.0, -1.0, 1.8], [0.0, 1.5, 1.8], [math.sin(roll), 0, math.cos(roll)], 40.0, W, H)
    img = avsplat.ground_truth(cam, supersample=8, footprint_sigma=sigma)
    variances = []
    for col in range(W):
        alpha = img.alpha[:, col].astype(np.float64)
        assert alpha[0] == 0 and alpha[-1] == 1
        lsf = np.diff(alpha)
        y = np.arange(len(lsf))
        mean = (y * lsf).sum() / lsf.sum()
        variances.append(((y - mean) ** 2 * lsf).sum() / lsf.sum())
    expected = 1 / 12 + sigma ** 2 + 1 / 12
    assert np.mean(variances) == pytest.approx(expected, abs=0.015)


def test_view_gains_have_the_promised_spread():
    exposure, wb = 0.3, 0.1
    kw = dict(views=240, width=6, height=5, target_views=0, seed=5)
    off = avsplat.simulate_predictions(**kw)
    on = avsplat.simulate_predictions(exposure_sigma=exposure, white_balance_sigma=wb, **kw)
    g = on.view_gains.astype(np.float64)
    assert np.std(np.log2(g[:, 1])) == pytest.approx(exposure, rel=0.15)
    assert np.std(np.log(g[:, 0] / g[:, 1])) == pytest.approx(wb, rel=0.15)
    assert np.std(np.log(g[:, 2] / g[:, 1])) == pytest.approx(wb, rel=0.15)
    assert abs(np.mean(np.log2(g[:, 1]))) < 4 * exposure / np.sqrt(240)
    # Every valid pixel's colour is the gain times the colour without gains, clipped at 1.
    expected = np.minimum(1.0, off.colors * g[:, None, None, :])
    v = on.valid
    np.testing.assert_allclose(on.colors[v], expected[v], atol=2e-6)
    np.testing.assert_array_equal(on.colors[~v], off.colors[~v])
    np.testing.assert_array_equal(off.view_gains, 1.0)


def test_specular_term_is_view_dependent_and_only_on_glossy_materials():
    cams = avsplat.target_cameras(views=6, width=64, height=48, target_views=3)
    for cam in cams:
        matte = avsplat.ground_truth(cam)
        shiny = avsplat.ground_truth(cam, specular=1.0)
        diff = np.abs(shiny.color - matte.color).max(axis=2)
        obj = matte.object_id
        # Only pixels whose footprint touches the sphere or the bunny change, and only upwards.
        glossy = np.isin(obj, [int(avsplat.SceneObject.Sphere), int(avsplat.SceneObject.Bunny)])
        near = glossy.copy()
        near[1:] |= glossy[:-1]; near[:-1] |= glossy[1:]; near[:, 1:] |= near[:, :-1].copy(); near[:, :-1] |= near[:, 1:].copy()
        assert diff[~near].max() == 0
        assert np.all(shiny.color >= matte.color - 1e-6)
    # The highlight moves with the view: the sphere's brightest pixel differs between views.
    tops = []
    for cam in cams:
        img = avsplat.ground_truth(cam, specular=1.0)
        sphere = img.object_id == int(avsplat.SceneObject.Sphere)
        extra = (img.color - avsplat.ground_truth(cam).color).sum(axis=2) * sphere
        assert extra.max() > 0.5
        hit = img.depth[np.unravel_index(np.argmax(extra), extra.shape)]
        tops.append(hit)
    assert len(set(np.round(tops, 3))) > 1


def test_mixed_pixels_match_the_coverage_rule():
    radius = 2.0
    kw = dict(views=2, width=48, height=36, target_views=0, seed=1)
    off = avsplat.simulate_predictions(**kw)
    on = avsplat.simulate_predictions(mixed_pixel_radius=radius, **kw)
    depth = _true_depth(off)
    offsets = [(dx, dy) for dy in range(-2, 3) for dx in range(-2, 3) if dx * dx + dy * dy <= radius * radius]
    S, H, W = off.valid.shape
    ref = off.colors.astype(np.float64).copy()
    mixed = np.zeros((S, H, W), bool)
    for s in range(S):
        cam = off.true_cameras[s]
        for y in range(H):
            for x in range(W):
                d = depth[s, y, x]
                if d <= 0:
                    continue
                step = 8 * d / math.sqrt(cam.fx * cam.fy)
                inside, other = 0, []
                for dx, dy in offsets:
                    qx, qy = x + dx, y + dy
                    if not (0 <= qx < W and 0 <= qy < H):
                        continue
                    inside += 1
                    dq = depth[s, qy, qx]
                    if dq <= 0 or abs(dq - d) > step:
                        other.append(off.colors[s, qy, qx].astype(np.float64))
                if other:
                    beta = len(other) / inside
                    ref[s, y, x] = (1 - beta) * ref[s, y, x] + beta * np.mean(other, axis=0)
                    mixed[s, y, x] = True
    np.testing.assert_allclose(on.colors, ref, atol=1e-5)
    # Mixed pixels are exactly those within the radius of an edge: a band around the silhouettes.
    changed = np.any(on.colors != off.colors, axis=-1)
    assert np.all(changed <= mixed)
    frac = mixed[off.valid].mean()
    assert 0.05 < frac < 0.6
    # Points are untouched: the depth error at edges is the flying-pixel model's.
    np.testing.assert_array_equal(on.points, off.points)


def test_attribute_noise_has_the_promised_std_scaled_by_uncertainty():
    a = 0.04
    kw = dict(views=3, width=64, height=48, target_views=0, seed=2)
    clean = avsplat.simulate_predictions(**kw)
    noisy = avsplat.simulate_predictions(attribute_noise=a, **kw)
    v = noisy.valid
    u = noisy.uncertainty[v].astype(np.float64)
    np.testing.assert_array_equal(u, clean.uncertainty[v])
    assert u.min() >= 1.0 and u.max() <= 5.0 and u.std() > 0.2
    assert np.all(noisy.uncertainty[~v] == 0)
    df = (noisy.features[v] - clean.features[v]).astype(np.float64) / u[:, None]
    # colour (SH degree 0 times C0), opacity logit, log scales
    assert np.std(df[:, 8:11] * C0) == pytest.approx(a, rel=0.05)
    assert np.std(df[:, 0]) == pytest.approx(5 * a, rel=0.05)
    assert np.std(df[:, 1:4]) == pytest.approx(2 * a, rel=0.05)
    np.testing.assert_array_equal(df[:, 4:8], 0)  # rotations are not noised
    # Noise is heavier where the model is unsure: the colour error grows with u.
    err = np.abs(noisy.appearance_error[v] - clean.appearance_error[v])
    assert err[u > 3].mean() > 1.5 * err[u < 1.5].mean()
    # The decoded per-pixel Gaussians carry the noise.
    g = noisy.decoded_gaussians()
    assert len(g) == int(v.sum())
    np.testing.assert_allclose(g.sh[:, 0, :], noisy.features[v][:, 8:11], atol=0)
    np.testing.assert_allclose(g.confidence, noisy.confidence[v])


def test_uncertainty_is_higher_at_edges_grazing_and_far():
    p = avsplat.simulate_predictions(views=2, width=64, height=48, target_views=0, seed=4, mixed_pixel_radius=1)
    v = p.valid
    depth = _true_depth(p)
    # Pixels whose colour mixed (radius 1: next to an edge) carry the edge term.
    off = avsplat.simulate_predictions(views=2, width=64, height=48, target_views=0, seed=4)
    edge = np.any(p.colors != off.colors, axis=-1) & v
    assert edge.sum() > 50
    assert np.all(p.uncertainty[edge] >= 2.0 - 1e-6)
    # Far pixels are less certain on average than near ones.
    d = depth[v]
    assert p.uncertainty[v][d > np.quantile(d, 0.9)].mean() > p.uncertainty[v][d < np.quantile(d, 0.5)].mean()


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9])
def test_confidence_has_the_requested_spearman_rho(rho):
    kw = dict(views=3, width=64, height=48, target_views=0, seed=6, attribute_noise=0.03, exposure_sigma=0.2)
    default = avsplat.simulate_predictions(**kw)
    p = avsplat.simulate_predictions(confidence_rho=rho, **kw)
    v = p.valid
    depth = _true_depth(p)
    total = p.true_error[v] / (0.01 * depth[v]) + p.appearance_error[v] / 0.05
    measured = _spearman(p.confidence[v].astype(np.float64), -total)
    assert measured == pytest.approx(p.confidence_spearman, abs=1e-3)
    assert measured == pytest.approx(rho, abs=0.03)
    # Only the assignment changes: the confidences are the default model's values.
    np.testing.assert_array_equal(np.sort(p.confidence[v]), np.sort(default.confidence[v]))
    # The opacity logit feature is the confidence plus its noise.
    assert np.corrcoef(p.features[v][:, 0], p.confidence[v])[0, 1] > 0.8
    # The default model reports its own rho (geometric information only; positive).
    assert default.confidence_spearman > 0.1


def test_results_do_not_depend_on_the_thread_count():
    code = ("import avsplat, hashlib, numpy as np\n"
            "p = avsplat.simulate_predictions(views=3, width=40, height=30, target_views=1, seed=9,"
            " footprint_sigma=0.6, exposure_sigma=0.2, white_balance_sigma=0.1, specular=0.8,"
            " mixed_pixel_radius=1.5, attribute_noise=0.05, confidence_rho=0.6)\n"
            "h = hashlib.sha256()\n"
            "for a in (p.points, p.colors, p.confidence, p.features, p.uncertainty, p.appearance_error,"
            " p.view_gains, avsplat.ground_truth(p.target_cameras[0], footprint_sigma=0.6, specular=0.8).color):\n"
            "    h.update(np.ascontiguousarray(a).tobytes())\n"
            "print(h.hexdigest(), repr(p.confidence_spearman))\n")
    out = []
    for threads in ("1", "2", "5"):
        env = dict(os.environ, OMP_NUM_THREADS=threads)
        out.append(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                  check=True).stdout)
    assert out[0] == out[1] == out[2]


def test_bad_error_model_options_raise_value_error():
    for kw, word in [(dict(footprint_sigma=-1), "footprint_sigma"), (dict(footprint_sigma=9), "footprint_sigma"),
                     (dict(exposure_sigma=float("nan")), "exposure_sigma"),
                     (dict(white_balance_sigma=-0.1), "white_balance_sigma"), (dict(specular=1.5), "specular"),
                     (dict(mixed_pixel_radius=-1), "mixed_pixel_radius"),
                     (dict(attribute_noise=float("inf")), "attribute_noise"),
                     (dict(confidence_rho=1.5), "confidence_rho")]:
        with pytest.raises(ValueError, match=word):
            avsplat.simulate_predictions(**SMALL, **kw)
