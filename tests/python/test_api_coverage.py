"""The public Python API as a whole: every name tested, documented and printable.

Three guards keep the API from rotting as it grows:
  - every public callable of ``avsplat`` (functions, classes, their public methods and
    properties) is mentioned by name in some test file;
  - every public function and method has a docstring beyond pybind11's signature line;
  - every class has its own ``__repr__`` (an instance of each is built here).
The rest tests the functions no other file covers, and the error paths (wrong shape ->
ValueError naming the argument, bad value -> ValueError naming the field, missing or unwritable
file -> OSError naming the file), against hand-built references.
"""
import inspect
import os
import pathlib
import re
import tempfile

import numpy as np
import pytest

import avsplat

C0 = 0.28209479177387814
TESTS = pathlib.Path(__file__).resolve().parent
# Module-level names that are not API of their own: submodules and the version string.
NOT_API = {"__version__"}


def public_api():
    """{"name": object} for avsplat's public callables and "Class.member" for class members."""
    api = {}
    for name in dir(avsplat):
        obj = getattr(avsplat, name)
        if name.startswith("_") or name in NOT_API or inspect.ismodule(obj) or not callable(obj):
            continue
        api[name] = obj
        if inspect.isclass(obj) and not issubclass(obj, BaseException):
            for member, value in vars(obj).items():
                if not member.startswith("_"):
                    api[f"{name}.{member}"] = value
    return api


def test_every_public_name_is_mentioned_in_a_test():
    # A module-level function must appear as avsplat.<name>; a member as .<member> (an
    # attribute access or call); a class by its name (result types are built by functions, and
    # test_every_class_has_its_own_repr builds one of each). A new public name without a test
    # fails here, naming it.
    text = "\n".join(p.read_text() for p in sorted(TESTS.glob("test_*.py")))
    missing = []
    for name, obj in sorted(public_api().items()):
        if "." in name:
            pattern = r"\." + re.escape(name.split(".")[1]) + r"\b"
        elif inspect.isclass(obj):
            pattern = r"\b" + re.escape(name) + r"\b"
        else:
            pattern = r"avsplat\." + re.escape(name) + r"\b"
        if not re.search(pattern, text):
            missing.append(name)
    assert not missing, f"public names no test mentions: {missing}"


def _doc_body(obj):
    """The docstring without pybind11's leading signature line(s)."""
    doc = inspect.getdoc(obj) or ""
    name = getattr(obj, "__name__", "")
    lines = [line for line in doc.splitlines() if not (name and line.startswith(name + "("))]
    return "\n".join(lines).strip()


def test_every_public_function_and_method_has_a_docstring():
    undocumented = []
    for name, obj in sorted(public_api().items()):
        if isinstance(obj, property):
            if not (obj.__doc__ or "").strip() and not _doc_body(getattr(avsplat, name.split(".")[0])):
                undocumented.append(name)
        elif isinstance(obj, (staticmethod, classmethod)):
            if not _doc_body(obj.__func__):
                undocumented.append(name)
        elif inspect.isroutine(obj) or inspect.isclass(obj):
            if inspect.isclass(obj) and issubclass(obj, BaseException):
                continue  # the exceptions are documented in the module docstring of _avsplat
            if not _doc_body(obj):
                undocumented.append(name)
    assert not undocumented, f"public names without a docstring: {undocumented}"


def test_help_of_fuse_gaussians_names_every_argument_and_knob():
    doc = avsplat.fuse_gaussians.__doc__
    for arg in ("cloud", "voxel_size", "policy", "shape", "tau0", "alpha", "n_ref", "tau_min", "tau_max",
                "b_conf", "b_geo", "k_rel", "eps", "trim_mass", "weights", "confidence_mapping", "on_invalid",
                "precision"):
        assert re.search(r"\b" + arg + r"\b", doc), arg


def small_cloud(n=3, k=1, seed=0):
    rng = np.random.default_rng(seed)
    return avsplat.GaussianCloud(rng.normal(size=(n, 3)), rng.uniform(0.05, 0.3, (n, 3)),
                                 rng.normal(size=(n, 4)), rng.uniform(0.2, 0.9, n),
                                 rng.normal(size=(n, k, 3)) * 0.3)


def one_of_each_class():
    """An instance of every public non-exception class, built the cheapest way."""
    cam = avsplat.Camera(40, 40, 16, 12, 32, 24)
    cam.name = "c0"
    cloud = small_cloud()
    cloud.means[:, 2] += 3.0
    pts = np.random.default_rng(1).uniform(0, 1, (20, 3))
    render = avsplat.render(cloud, cam)
    instances = {
        "Camera": cam,
        "GaussianCloud": cloud,
        "SanitizeReport": cloud.copy().sanitize(),
        "RenderResult": render,
        "RenderStats": render.stats,
        "AccuracyCompleteness": avsplat.accuracy_completeness(pts, pts + 0.01, 0.1),
        "SparseVoxelGrid": avsplat.SparseVoxelGrid(pts, 0.5),
        "FeatureFusionResult": avsplat.fuse_voxels(pts, pts, 0.5),
        "FusionStream": avsplat.FusionStream(0.5),
        "GaussianPlyWriter": avsplat.GaussianPlyWriter(os.path.join(tempfile.mkdtemp(), "never-committed.ply")),
        "GaussianFusionResult": avsplat.fuse_gaussians(cloud, 0.5),
        "ViewCoverage": avsplat.select_views_by_coverage(pts[None], 0.5),
        "FeatureLayout": avsplat.FeatureLayout(),
        "PruneResult": avsplat.prune(cloud, [cam]),
        "ReduceShResult": avsplat.reduce_sh(cloud),
        "SimplifyResult": avsplat.simplify(cloud, target_count=2),
        "AssistSelection": avsplat.select_assist_views(pts.reshape(4, 5, 3)),
        "RenderWorkspace": avsplat.RenderWorkspace(),
    }
    with tempfile.TemporaryDirectory() as folder:
        avsplat.write_ply(os.path.join(folder, "a.ply"), cloud)
        instances["GaussianFormatInfo"] = avsplat.detect_gaussian_format(os.path.join(folder, "a.ply"))
        np.savez(os.path.join(folder, "p.npz"), points=pts, features=pts)
        instances["PredictionSamples"] = avsplat.read_prediction_npz(os.path.join(folder, "p.npz"))
        instances["LodBuild"] = avsplat.build_lod(cloud, os.path.join(folder, "lod-meta.json"), levels=2)
        instances["LodSetInfo"] = avsplat.read_lod_set_info(os.path.join(folder, "lod-meta.json"))
    if hasattr(avsplat, "simulate_predictions"):
        instances["Predictions"] = avsplat.simulate_predictions(views=2, width=8, height=6, target_views=0,
                                                                supersample=1)
        instances["GroundTruthImage"] = avsplat.ground_truth(cam, supersample=1)
        instances["SceneObject"] = avsplat.SceneObject.Bunny
        capture = avsplat.simulate_chunked_capture(frames=8, window=5, overlap=3, width=16, height=12, target_views=0)
        chunks = [c.prediction_chunk() for c in capture.chunks]
        stitched = avsplat.stitch(chunks, 0.5, min_correspondences=3)
        instances.update(ChunkedCapture=capture, CaptureChunk=capture.chunks[0], PredictionChunk=chunks[0],
                         StitchResult=stitched, ChunkAlignment=stitched.alignment,
                         PairAlignment=stitched.alignment.pairs[0], Similarity=avsplat.Similarity(),
                         SimilarityFit=avsplat.similarity_from_correspondences(pts, pts))
    return instances


def test_every_class_has_its_own_repr():
    instances = one_of_each_class()
    classes = [n for n, o in vars(avsplat).items()
               if inspect.isclass(o) and not n.startswith("_") and not issubclass(o, BaseException)]
    assert sorted(classes) == sorted(instances), "add an instance of each new class to one_of_each_class()"
    for name, obj in instances.items():
        text = repr(obj)
        assert name in text and " object at 0x" not in text, (name, text)
    assert repr(instances["SanitizeReport"]) == "SanitizeReport(kept 3, dropped 0)"
    assert repr(instances["SceneObject"]) == "<SceneObject.Bunny: 2>"
    assert repr(instances["Camera"]).endswith("name='c0')")
    acc = instances["AccuracyCompleteness"]
    assert acc.threshold == 0.1 and "threshold=0.1)" in repr(acc)


def test_exceptions_map_to_the_python_hierarchy():
    assert issubclass(avsplat.IOError, OSError)
    assert issubclass(avsplat.DeviceError, RuntimeError)


# ---- GaussianCloud ----------------------------------------------------------------------------

def test_sanitize_report_counts_each_reason():
    cloud = small_cloud(n=5)
    cloud.scales[1, 0] = -1.0
    cloud.rotations[2] = 0.0
    cloud.means[3, 1] = np.nan
    report = cloud.sanitize()
    assert (report.kept, report.dropped) == (2, 3)
    assert (report.negative_scale, report.zero_rotation, report.non_finite, report.opacity_range) == (1, 1, 1, 0)
    assert "dropped 3" in report.summary() and len(cloud) == 2


def test_gaussian_cloud_member_error_paths():
    cloud = small_cloud(n=2)
    with pytest.raises(IndexError, match="index 5 >= size 2"):
        cloud.covariance(5)
    with pytest.raises(ValueError, match="empty"):
        avsplat.GaussianCloud.empty(0).bounding_box()
    with pytest.raises(ValueError, match="mask has 1 entries, the cloud 2"):
        cloud.select_mask([True])
    with pytest.raises(IndexError, match=r"indices\[0\] = 5 >= size 2"):
        cloud.select([5])
    with pytest.raises(ValueError, match=r"values: expected shape \(N\), got \(3,\)"):
        cloud.set_extra("a", [1, 2, 3])
    with pytest.raises(ValueError, match="sh_degree 5"):
        avsplat.GaussianCloud.empty(2, 5)
    with pytest.raises(ValueError, match=r"sh: K = 5"):
        avsplat.GaussianCloud(np.zeros((2, 3)), np.ones((2, 3)), [[1, 0, 0, 0]] * 2, [1, 1], np.zeros((2, 5, 3)))
    with pytest.raises(TypeError):
        avsplat.concatenate([cloud, "not a cloud"])


def test_covariance_and_bounding_box_against_numpy():
    cloud = small_cloud(n=4, seed=3)
    q = cloud.rotations[2].astype(np.float64)
    w, x, y, z = q / np.linalg.norm(q)
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    S = np.diag(cloud.scales[2].astype(np.float64))
    np.testing.assert_allclose(cloud.covariance(2), R @ S @ S @ R.T, atol=1e-7)
    lo, hi = cloud.bounding_box()
    np.testing.assert_array_equal(lo, cloud.means.min(axis=0))
    np.testing.assert_array_equal(hi, cloud.means.max(axis=0))
    c2 = cloud.copy()
    c2.means[0] = 99.0  # a deep copy: the original is untouched
    assert cloud.means[0, 0] != 99.0


def test_sh_degree_for_coeffs():
    got = {k: avsplat.sh_degree_for_coeffs(k) for k in range(0, 18)}
    assert {k: d for k, d in got.items() if d >= 0} == {1: 0, 4: 1, 9: 2, 16: 3}
    assert all(d == -1 for k, d in got.items() if k not in (1, 4, 9, 16))


# ---- I/O --------------------------------------------------------------------------------------

def splat_records(n):
    return np.zeros(n, dtype=[("p", "<f4", 3), ("s", "<f4", 3), ("c", "u1", 4), ("q", "u1", 4)])


def test_read_splat_decodes_a_hand_built_file(tmp_path):
    # The antimatter15 record: position, linear scale (float32), RGBA bytes (colour = 0.5 + C0 dc,
    # A = opacity), quaternion bytes (q * 128 + 128).
    rec = splat_records(2)
    rec["p"] = [[1, 2, 3], [-1, 0.5, 0.25]]
    rec["s"] = [[0.1, 0.2, 0.3], [0.01, 0.02, 0.03]]
    rec["c"] = [[255, 128, 0, 200], [10, 20, 30, 40]]
    rec["q"] = [[255, 128, 128, 128], [128, 255, 128, 128]]
    rec.tofile(tmp_path / "hand.splat")
    c = avsplat.read_splat(tmp_path / "hand.splat")
    assert len(c) == 2 and c.sh_degree == 0 and c.confidence is None
    np.testing.assert_array_equal(c.means, rec["p"])
    np.testing.assert_array_equal(c.scales, rec["s"])
    np.testing.assert_allclose(c.opacities, rec["c"][:, 3] / 255.0, rtol=1e-6)
    np.testing.assert_allclose(0.5 + C0 * c.sh[:, 0, :], rec["c"][:, :3] / 255.0, atol=1e-6)
    np.testing.assert_allclose(c.rotations, (rec["q"].astype(np.float64) - 128) / 128, atol=1e-7)


def test_write_splat_quantises_and_orders_by_volume_times_opacity(tmp_path):
    cloud = small_cloud(n=6, seed=4)
    avsplat.write_splat(tmp_path / "w.splat", cloud)
    rec = np.fromfile(tmp_path / "w.splat", dtype=splat_records(0).dtype)
    order = np.argsort(-(np.prod(cloud.scales.astype(np.float64), axis=1) * cloud.opacities), kind="stable")
    np.testing.assert_array_equal(rec["p"], cloud.means[order])
    np.testing.assert_array_equal(rec["s"], cloud.scales[order])
    rgb = np.clip(np.rint(255 * (0.5 + C0 * cloud.sh[order, 0, :].astype(np.float64))), 0, 255)
    np.testing.assert_array_equal(rec["c"][:, :3], rgb)
    np.testing.assert_array_equal(rec["c"][:, 3], np.rint(255 * cloud.opacities[order].astype(np.float64)))


def test_splat_and_dispatch_errors_name_the_file(tmp_path):
    (tmp_path / "bad.splat").write_bytes(b"x" * 33)
    with pytest.raises(OSError, match=r"bad\.splat: size 33 bytes is not a multiple"):
        avsplat.read_splat(tmp_path / "bad.splat")
    rec = splat_records(1)
    rec["q"] = 128  # decodes to the zero quaternion
    rec.tofile(tmp_path / "zero.splat")
    with pytest.raises(OSError, match="record 0 has a zero quaternion"):
        avsplat.read_splat(tmp_path / "zero.splat")
    with pytest.raises(OSError, match=r"none\.splat: cannot open"):
        avsplat.read_splat(tmp_path / "none.splat")
    with pytest.raises(OSError, match="cannot open for writing"):
        avsplat.write_splat(tmp_path / "no_dir" / "a.splat", small_cloud())
    # Reading detects the format from the content: a missing file is reported as such.
    with pytest.raises(OSError, match=r"a\.xyz: cannot open for reading"):
        avsplat.read_gaussians(tmp_path / "a.xyz")
    with pytest.raises(OSError, match=r"none\.ply"):
        avsplat.read_gaussians(tmp_path / "none.ply")


def test_read_gaussians_dispatches_ply(tmp_path):
    cloud = small_cloud(n=4, k=4, seed=2)
    avsplat.write_gaussians(tmp_path / "a.ply", cloud)
    back = avsplat.read_gaussians(tmp_path / "a.ply")
    assert back.sh_degree == 1
    np.testing.assert_array_equal(back.means, cloud.means)
    np.testing.assert_array_equal(back.sh, cloud.sh)


def test_camera_json_errors_name_the_file(tmp_path):
    cam = avsplat.Camera(40, 40, 16, 12, 32, 24)
    with pytest.raises(OSError, match=r"missing\.json: cannot open for reading"):
        avsplat.read_cameras_json(tmp_path / "missing.json")
    with pytest.raises(OSError, match=r"missing\.json"):
        avsplat.read_camera_json(tmp_path / "missing.json")
    with pytest.raises(OSError, match="cannot open for writing"):
        avsplat.write_camera_json(tmp_path / "no_dir" / "c.json", cam)
    with pytest.raises(OSError, match="cannot open for writing"):
        avsplat.write_cameras_json(tmp_path / "no_dir" / "c.json", [cam])
    avsplat.write_cameras_json(tmp_path / "two.json", [cam, cam])
    with pytest.raises(OSError, match="camera index 5 out of range"):
        avsplat.read_camera_json(tmp_path / "two.json", 5)
    (tmp_path / "bad.json").write_text("{ not json")
    with pytest.raises(OSError, match=r"bad\.json"):
        avsplat.read_cameras_json(tmp_path / "bad.json")


def test_camera_to_world_is_the_inverse():
    cam = avsplat.Camera.look_at([1.0, -2.0, 3.0], [0.2, 0.1, 0.0], [0, 1, 0], 50.0, 64, 48)
    np.testing.assert_allclose(cam.camera_to_world() @ cam.world_to_camera, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(cam.camera_to_world()[:3, 3], cam.position, atol=1e-12)


# ---- Images -----------------------------------------------------------------------------------

def test_turbo_colormap_endpoints_clamp_and_type_error():
    # Google's published turbo polynomial at 0 and 1.
    np.testing.assert_allclose(avsplat.turbo_colormap(0.0), [0.19, 0.0718, 0.2322], atol=1e-3)
    np.testing.assert_allclose(avsplat.turbo_colormap(1.0), [0.4796, 0.0158, 0.0106], atol=1e-3)
    assert avsplat.turbo_colormap(2.0) == avsplat.turbo_colormap(1.0)
    assert avsplat.turbo_colormap(-1.0) == avsplat.turbo_colormap(0.0)
    with pytest.raises(TypeError):
        avsplat.turbo_colormap("red")


def test_png_writers_error_paths(tmp_path):
    with pytest.raises(ValueError, match=r"alpha: expected shape \(H, W\), got \(4, 4, 3\)"):
        avsplat.write_alpha_png(tmp_path / "a.png", np.zeros((4, 4, 3)))
    with pytest.raises(ValueError, match=r"depth: expected shape \(H, W\), got \(4,\)"):
        avsplat.write_depth_png(tmp_path / "d.png", np.zeros(4))
    with pytest.raises(ValueError, match=r"must end in \.png"):
        avsplat.write_depth_png(tmp_path / "d.jpg", np.ones((4, 4)))
    with pytest.raises(OSError, match="cannot write"):
        avsplat.write_alpha_png(tmp_path / "no_dir" / "a.png", np.zeros((4, 4)))


def test_render_stats_timings_are_reported():
    cloud = small_cloud()
    cloud.means[:, 2] += 3.0
    s = avsplat.render(cloud, avsplat.Camera(40, 40, 16, 12, 32, 24)).stats
    stages = (s.seconds_projection, s.seconds_sorting, s.seconds_blending)
    assert all(t >= 0 for t in stages) and s.seconds_total >= 0


def test_render_stats_counters_of_one_splat():
    # One small Gaussian projected around pixel (8, 8): its 3-sigma box lies inside the first
    # 16 x 16 tile, so it has exactly one tile instance.
    z = 5.0
    cloud = avsplat.GaussianCloud([[(8 - 16) / 40 * z, (8 - 12) / 40 * z, z]], [[0.05] * 3], [[1, 0, 0, 0]], [0.9],
                                  np.zeros((1, 1, 3)))
    r = avsplat.render(cloud, avsplat.Camera(40, 40, 16, 12, 32, 24))
    s = r.stats
    assert (s.gaussians, s.visible, s.tile_instances) == (1, 1, 1)
    assert s.contributions == r.contributors.sum() == np.count_nonzero(r.alpha)
    assert s.blends >= s.contributions > 0 and s.threads >= 1
    assert "visible 1/1" in s.summary()


def test_to_open3d_module_functions():
    cloud = small_cloud(n=4, k=4)
    pcd = avsplat.to_open3d(cloud)
    np.testing.assert_array_equal(pcd.point.positions.numpy(), cloud.means)
    legacy = avsplat.to_open3d_legacy(cloud)
    np.testing.assert_allclose(np.asarray(legacy.colors),
                               np.clip(0.5 + C0 * cloud.sh[:, 0, :].astype(np.float64), 0, 1), atol=1e-12)
    cloud.scales[1, 0] = -1.0
    with pytest.raises(ValueError, match=r"scales\[1\]: negative scale"):
        avsplat.to_open3d(cloud)
    with pytest.raises(AttributeError):
        avsplat.to_open3d_legacy(np.zeros((4, 3)))


def test_cuda_device_count_agrees_with_the_cuda_backend():
    n = avsplat.cuda_device_count()
    assert isinstance(n, int) and n >= 0
    if n == 0:
        with pytest.raises(avsplat.DeviceError):
            avsplat.render(small_cloud(), avsplat.Camera(40, 40, 16, 12, 32, 24), backend="cuda")


# ---- Point sets -------------------------------------------------------------------------------

def test_point_set_error_paths():
    good = np.zeros((3, 3))
    with pytest.raises(ValueError, match=r"source: expected shape \(N, 3\), got \(3, 2\)"):
        avsplat.compute_point_cloud_distance(np.zeros((3, 2)), good)
    with pytest.raises(ValueError, match=r"target: expected shape \(N, 3\), got \(3,\)"):
        avsplat.compute_point_cloud_distance(good, np.zeros(3))
    with pytest.raises(ValueError, match=r"points: expected shape \(N, 3\)"):
        avsplat.remove_statistical_outliers(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="nb_neighbors must be >= 1"):
        avsplat.remove_statistical_outliers(np.random.default_rng(0).random((10, 3)), nb_neighbors=0)
    with pytest.raises(ValueError, match="std_ratio"):
        avsplat.remove_statistical_outliers(np.random.default_rng(0).random((10, 3)), 3, -1.0)


# ---- Simulator --------------------------------------------------------------------------------

needs_simulator = pytest.mark.skipif(not hasattr(avsplat, "simulate_predictions"),
                                     reason="avsplat built without Open3D (no simulator)")


@needs_simulator
def test_input_cameras_geometry_and_errors():
    cams = avsplat.input_cameras(views=3, width=32, height=24, fov_y=60.0)
    assert len(cams) == 3 and all((c.width, c.height) == (32, 24) for c in cams)
    np.testing.assert_allclose([c.fy for c in cams], 12 / np.tan(np.radians(30)), rtol=1e-12)
    assert len({tuple(np.round(c.position, 9)) for c in cams}) == 3  # distinct poses
    # The simulator's true cameras are these.
    p = avsplat.simulate_predictions(views=3, width=32, height=24, fov_y=60.0, target_views=0, supersample=1)
    for a, b in zip(cams, p.true_cameras):
        np.testing.assert_allclose(a.world_to_camera, b.world_to_camera, atol=1e-12)
    with pytest.raises(ValueError, match="SimulatorOptions.views"):
        avsplat.input_cameras(views=0)
    with pytest.raises(ValueError, match="SimulatorOptions.width"):
        avsplat.input_cameras(views=3, width=0)


@needs_simulator
def test_ground_truth_and_bunny_errors_and_shapes():
    cam = avsplat.input_cameras(views=1, width=16, height=12)[0]
    with pytest.raises(ValueError, match="SimulatorOptions.supersample"):
        avsplat.ground_truth(cam, supersample=0)
    with pytest.raises(ValueError, match=r"background: expected shape \(3\), got \(2,\)"):
        avsplat.ground_truth(cam, 1, (0.0, 0.0))
    with pytest.raises(ValueError, match="SimulatorOptions.target_views"):
        avsplat.target_cameras(views=3, target_views=5)
    v, f = avsplat.bunny_mesh()
    assert v.dtype == np.float64 and f.dtype == np.int32 and v.shape[1] == f.shape[1] == 3
    assert f.min() >= 0 and f.max() < len(v)


@needs_simulator
def test_scene_object_values_are_the_object_ids():
    values = {o: o.value for o in (avsplat.SceneObject.Background, avsplat.SceneObject.Ground,
                                   avsplat.SceneObject.Wall, avsplat.SceneObject.Bunny, avsplat.SceneObject.Sphere)}
    assert list(values.values()) == [-1, 0, 1, 2, 3]
    p = avsplat.simulate_predictions(views=2, width=24, height=18, target_views=0, supersample=1)
    assert set(np.unique(p.object_id)) <= set(values.values())


# ---- One conversion rule: float64 and Fortran order give the float32 C-order result -----------

def as_f64_fortran(a):
    out = np.asfortranarray(np.asarray(a, np.float64))
    assert not out.flags.c_contiguous or out.ndim < 2
    return out


def test_float64_fortran_inputs_match_float32_c_inputs():
    rng = np.random.default_rng(7)
    n = 300
    means = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    means[:, 2] += 4.0
    scales = rng.uniform(0.02, 0.2, (n, 3)).astype(np.float32)
    quats = rng.normal(size=(n, 4)).astype(np.float32)
    opac = rng.uniform(0.1, 0.9, n).astype(np.float32)
    sh = (rng.normal(size=(n, 4, 3)) * 0.3).astype(np.float32)
    conf = rng.normal(size=n).astype(np.float32)

    c32 = avsplat.GaussianCloud(means, scales, quats, opac, sh, confidence=conf)
    c64 = avsplat.GaussianCloud(*(as_f64_fortran(a) for a in (means, scales, quats, opac, sh)),
                                confidence=conf.astype(np.float64))
    for name in ("means", "scales", "rotations", "opacities", "sh", "confidence"):
        assert getattr(c64, name).flags.c_contiguous and getattr(c64, name).dtype == np.float32
        np.testing.assert_array_equal(getattr(c64, name), getattr(c32, name))

    cam = avsplat.Camera(60, 60, 24, 18, 48, 36)
    r32, r64 = avsplat.render(c32, cam), avsplat.render(c64, cam)
    np.testing.assert_array_equal(r64.color, r32.color)
    np.testing.assert_array_equal(r64.depth, r32.depth)

    feats = rng.normal(size=(n, 5)).astype(np.float32)
    f32 = avsplat.fuse_voxels(means, feats, 0.3, confidence=conf)
    f64 = avsplat.fuse_voxels(as_f64_fortran(means), as_f64_fortran(feats), 0.3, confidence=conf.astype(np.float64))
    np.testing.assert_array_equal(f64.positions, f32.positions)
    np.testing.assert_array_equal(f64.features, f32.features)
    np.testing.assert_array_equal(f64.voxel_coords, f32.voxel_coords)

    g32, g64 = avsplat.SparseVoxelGrid(means, 0.3), avsplat.SparseVoxelGrid(as_f64_fortran(means), 0.3)
    np.testing.assert_array_equal(g64.sample_indices, g32.sample_indices)

    # A strided view (every other row) is converted by the same rule.
    np.testing.assert_array_equal(avsplat.fuse_voxels(np.repeat(means, 2, axis=0)[::2], feats, 0.3).features,
                                  avsplat.fuse_voxels(means, feats, 0.3).features)
