"""Registration and stitching from Python: similarity fits against numpy references, chunk
alignment and stitching on simulated chunked captures against their true transforms."""

import numpy as np
import pytest

import avsplat


def _random_similarity(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return avsplat.Similarity(r, rng.uniform(-2, 2, 3), float(np.exp(rng.uniform(-0.7, 0.7))))


def _angle_deg(a, b):
    c = (np.trace(a.T @ b) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(c, -1, 1))))


def test_similarity_algebra_matches_matrices():
    rng = np.random.default_rng(0)
    a, b = _random_similarity(rng), _random_similarity(rng)
    np.testing.assert_allclose((a @ b).matrix(), a.matrix() @ b.matrix(), atol=1e-12)
    np.testing.assert_allclose(a.inverse().matrix(), np.linalg.inv(a.matrix()), atol=1e-12)
    p = rng.normal(size=(5, 3))
    np.testing.assert_allclose(a.apply(p), p @ (a.scale * a.rotation).T + a.translation, atol=1e-12)
    assert "Similarity(" in repr(a)


def test_similarity_from_correspondences_matches_weighted_umeyama_in_numpy():
    rng = np.random.default_rng(1)
    truth = _random_similarity(rng)
    src = rng.normal(size=(300, 3))
    dst = truth.apply(src) + 0.01 * rng.normal(size=(300, 3))
    w = rng.uniform(0.1, 1.0, 300)
    fit = avsplat.similarity_from_correspondences(src, dst, w, loss_scale=0.0)
    # Reference: Umeyama (1991) with weights, in float64 numpy (inputs rounded to float32 as the
    # binding reads them).
    s, d = src.astype(np.float32).astype(np.float64), dst.astype(np.float32).astype(np.float64)
    ww = w.astype(np.float32) / w.astype(np.float32).sum()
    ms, md = ww @ s, ww @ d
    cov = ((d - md) * ww[:, None]).T @ (s - ms)
    u, sv, vt = np.linalg.svd(cov)
    sign = np.diag([1, 1, np.sign(np.linalg.det(u) * np.linalg.det(vt))])
    r = u @ sign @ vt
    scale = np.trace(np.diag(sv) @ sign) / (ww @ ((s - ms) ** 2).sum(axis=1))
    np.testing.assert_allclose(fit.transform.rotation, r, atol=1e-9)
    assert fit.transform.scale == pytest.approx(scale, rel=1e-9)
    np.testing.assert_allclose(fit.transform.translation, md - scale * r @ ms, atol=1e-9)
    assert "SimilarityFit(" in repr(fit)
    # Without a loss every weight is the input's: the effective count is (sum w)^2 / sum w^2.
    assert fit.effective_count == pytest.approx(w.astype(np.float32).sum() ** 2 / (w.astype(np.float32) ** 2).sum(),
                                                rel=1e-6)
    assert fit.scene_size == pytest.approx(np.sqrt(ww @ ((d - md) ** 2).sum(axis=1)), rel=1e-6)
    assert 0.005 < fit.rms_residual < 0.03  # noise of 0.01 per axis: about 0.017
    with pytest.raises(ValueError, match="collinear"):
        avsplat.similarity_from_correspondences(np.outer(np.arange(5), [1, 2, 3]), src[:5])


@pytest.fixture(scope="module")
def capture():
    return avsplat.sim.simulate_chunked_capture(frames=40, window=12, overlap=4, width=40, height=30,
                                                target_views=2, seed=3)


def test_align_chunks_recovers_true_transforms(capture):
    chunks = [c.prediction_chunk(f"w{i}") for i, c in enumerate(capture.chunks)]
    assert "PredictionChunk(name='w0'" in repr(chunks[0])
    assert "ChunkedCapture(40 frames" in repr(capture) and "CaptureChunk(frames 0..11" in repr(capture.chunks[0])
    for pose_graph in (True, False):
        al = avsplat.align_chunks(chunks, pose_graph=pose_graph)
        assert "ChunkAlignment(" in repr(al) and "PairAlignment(" in repr(al.pairs[0])
        w0 = capture.chunks[0].world_from_chunk
        for i, c in enumerate(capture.chunks[1:], 1):
            truth = w0.inverse() @ c.world_from_chunk
            est = al.transforms[i]
            assert _angle_deg(est.rotation, truth.rotation) < 0.5
            assert est.scale / truth.scale == pytest.approx(1.0, rel=0.01)
            assert np.linalg.norm(est.translation - truth.translation) < 0.03 / w0.scale
        assert all(r > 0 for r in al.residuals)
        # Consecutive windows share frames; each pair's fit and its residual after alignment.
        assert [(p.a, p.b) for p in al.pairs] == [(i, i + 1) for i in range(len(chunks) - 1)]
        for p in al.pairs:
            assert p.correspondences >= 64 and 0 < p.rms_residual < 0.05 * p.scene_size
            assert p.aligned_rms > 0
            direct = w0.inverse() @ capture.chunks[p.a].world_from_chunk
            truth_ab = direct.inverse() @ w0.inverse() @ capture.chunks[p.b].world_from_chunk
            assert p.a_from_b.scale / truth_ab.scale == pytest.approx(1.0, rel=0.01)
        if pose_graph:
            assert al.final_cost <= al.initial_cost


def test_chunk_frames_are_similar_copies_of_the_world(capture):
    # The true points of a chunk, moved by its true transform, are the trajectory's true points.
    c = capture.chunks[1]
    p = c.predictions
    ids = c.frame_ids
    world = capture.trajectory.true_points[ids][p.valid]
    moved = c.world_from_chunk.apply(p.true_points[p.valid].reshape(-1, 3))
    np.testing.assert_allclose(moved, world, atol=1e-4)


def test_stitch_is_within_reach_of_the_true_transform_fusion(capture):
    chunks = [c.prediction_chunk() for c in capture.chunks]
    w0 = capture.chunks[0].world_from_chunk
    voxel = 0.02 / w0.scale
    result = avsplat.stitch(chunks, voxel, "occupancy")
    assert "StitchResult(" in repr(result)
    assert result.input_gaussians == sum(len(c.gaussians) for c in chunks) > len(result.cloud)
    assert len(result.alignment.transforms) == len(chunks)
    truth = [w0.inverse() @ c.world_from_chunk for c in capture.chunks]
    ceiling = avsplat.fuse_chunks(chunks, truth, voxel, "occupancy")
    assert abs(len(result.cloud) - len(ceiling)) < 0.05 * len(ceiling)
    # Render both, moved into the world, from a held-out view.
    cam = capture.trajectory.target_cameras[0]
    a = avsplat.render(avsplat.transform(result.cloud, w0.rotation, w0.translation, w0.scale), cam).color
    b = avsplat.render(avsplat.transform(ceiling, w0.rotation, w0.translation, w0.scale), cam).color
    assert avsplat.psnr(a, b) > 30
    streamed = avsplat.stitch(chunks, voxel, "occupancy", memory_limit=1 << 20)
    np.testing.assert_array_equal(streamed.cloud.means, result.cloud.means)


def test_stitch_reads_chunks_from_npz(tmp_path, capture):
    paths = []
    for i, c in enumerate(capture.chunks[:2]):
        p = c.predictions
        path = tmp_path / f"chunk{i}.npz"
        np.savez(path, points=p.points, colors=p.colors, valid=p.valid, confidence=p.confidence,
                 frame_ids=c.frame_ids)
        paths.append(path)
    chunks = [avsplat.read_prediction_chunk(p) for p in paths]
    assert list(chunks[1].frame_ids) == list(capture.chunks[1].frame_ids)
    result = avsplat.stitch(chunks, 0.05)
    assert len(result.cloud) > 0
    np.savez(tmp_path / "bad.npz", points=capture.chunks[0].predictions.points)
    with pytest.raises(avsplat.FileError, match="frame_ids"):
        avsplat.read_prediction_chunk(tmp_path / "bad.npz")


def test_bad_chunks_are_named(capture):
    p = capture.chunks[0].predictions
    with pytest.raises(ValueError, match="chunk 'lonely': no valid pixel"):
        avsplat.PredictionChunk(p.points, capture.chunks[0].frame_ids, valid=np.zeros_like(p.valid), name="lonely")
    a = avsplat.PredictionChunk(p.points, capture.chunks[0].frame_ids, valid=p.valid, name="a")
    q = capture.chunks[1].predictions
    b = avsplat.PredictionChunk(q.points, capture.chunks[1].frame_ids + 1000, valid=q.valid, name="b")
    with pytest.raises(ValueError, match=r"chunk 1 \('b'\) shares no frames"):
        avsplat.align_chunks([a, b])
    with pytest.raises(ValueError, match="has no Gaussians"):
        avsplat.fuse_chunks([a], [avsplat.Similarity()], 0.1)


def test_simulate_chunked_capture_is_deterministic_and_checks_options():
    a = avsplat.simulate_chunked_capture(frames=12, window=6, overlap=2, width=16, height=12, seed=5)
    b = avsplat.sim.simulate_chunked_capture(frames=12, window=6, overlap=2, width=16, height=12, seed=5)
    assert [list(c.frame_ids) for c in a.chunks] == [list(range(0, 6)), list(range(4, 10)), list(range(6, 12))]
    for x, y in zip(a.chunks, b.chunks):
        np.testing.assert_array_equal(x.predictions.points, y.predictions.points)
    with pytest.raises(ValueError, match="overlap"):
        avsplat.sim.simulate_chunked_capture(frames=12, window=6, overlap=6)
