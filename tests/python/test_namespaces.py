"""The Python package's layout: subpackages that mirror the C++ modules, a top level that keeps
every name it ever had, an ``__all__`` of the product's main names, and no builtin shadowed."""
import builtins
import importlib
import subprocess
import sys

import numpy as np
import pytest

import avsplat

# Every public name of the top level before the subpackages existed: users' scripts call them as
# avsplat.<name>, so each must keep resolving.
FORMER_TOP_LEVEL = """
Camera DeviceError GaussianCloud IOError SanitizeReport concatenate read_camera_json read_cameras_json
read_gaussians read_ply read_ply_data read_splat sh_degree_for_coeffs write_camera_json write_cameras_json
write_gaussians write_ply GaussianPlyWriter write_splat AccuracyCompleteness accuracy_completeness
chamfer_distance compute_point_cloud_distance gaussians_from_point_maps remove_statistical_outliers
RenderResult RenderStats cuda_device_count psnr render ssim RenderWorkspace defaults FeatureFusionResult
FeatureLayout FusionStream GaussianFusionResult SparseVoxelGrid fuse_gaussians fuse_voxels decode_gaussians
encode_gaussians turbo_colormap write_alpha_png write_color_png write_depth_png GroundTruthImage Predictions
SceneObject bunny_mesh ground_truth input_cameras scene_color simulate_predictions target_cameras
ViewCoverage select_views_by_coverage PruneResult ReduceShResult prune reduce_sh read_sog write_sog
SimplifyResult simplify AssistSelection assist_objective condition_tokens select_assist_views __version__
from_open3d to_open3d to_open3d_legacy read_spz read_spz_header write_spz GaussianFormatInfo
coordinate_system_change detect_gaussian_format morton_order read_compressed_ply sh_rotation transform
write_compressed_ply
""".split()

SUBPACKAGES = ["core", "io", "fusion", "render", "reduce", "metrics", "point_maps", "predictions", "assist",
               "sim", "eval", "dask", "open3d", "view"]


def test_every_former_top_level_name_still_resolves():
    missing = [name for name in FORMER_TOP_LEVEL if not hasattr(avsplat, name)]
    assert not missing


@pytest.mark.parametrize("name", SUBPACKAGES)
def test_subpackage_imports_and_its_names_are_the_top_level_objects(name):
    module = importlib.import_module(f"avsplat.{name}")
    assert getattr(avsplat, name) is module
    for public in getattr(module, "__all__", []):
        assert hasattr(module, public), f"avsplat.{name}.__all__ names missing {public}"
        if name in ("eval", "dask") or (name, public) == ("render", "render"):
            continue  # their names live in the subpackage only; avsplat.render is the module
        assert getattr(avsplat, public) is getattr(module, public), f"avsplat.{public} differs from avsplat.{name}'s"


def test_each_name_lives_in_the_subpackage_of_its_cpp_module():
    assert avsplat.io.read_ply is avsplat.read_ply
    assert avsplat.fusion.fuse_gaussians is avsplat.fuse_gaussians
    assert avsplat.reduce.simplify is avsplat.simplify
    assert avsplat.metrics.psnr is avsplat.psnr
    assert avsplat.point_maps.gaussians_from_point_maps is avsplat.gaussians_from_point_maps
    assert avsplat.sim.simulate_predictions is avsplat.simulate_predictions
    assert avsplat.assist.select_views_by_coverage is avsplat.select_views_by_coverage
    assert avsplat.open3d.to_open3d is avsplat.to_open3d
    assert avsplat.eval.REPORTS is avsplat.evaluation.REPORTS


def test_all_lists_the_product_names_and_leaves_out_the_simulator_and_reports():
    assert set(avsplat.__all__) <= set(dir(avsplat))
    for name in ("GaussianCloud", "Camera", "read_gaussians", "write_gaussians", "fuse_gaussians", "render",
                 "psnr", "ssim", "simplify", "prune", "FileError"):
        assert name in avsplat.__all__
    for name in ("simulate_predictions", "bunny_mesh", "condition_tokens", "IOError", "ground_truth"):
        assert name not in avsplat.__all__
    assert len(avsplat.__all__) == len(set(avsplat.__all__))


def test_star_import_does_not_shadow_a_builtin():
    namespace = {}
    exec("from avsplat import *", namespace)
    shadowed = [name for name in namespace if name != "__builtins__" and hasattr(builtins, name)]
    assert not shadowed
    for name in SUBPACKAGES:
        namespace = {}
        exec(f"from avsplat.{name} import *", namespace)
        assert not [n for n in namespace if n != "__builtins__" and hasattr(builtins, n)], name


def test_file_error_is_an_oserror_with_its_own_name_and_iOError_is_its_alias(tmp_path):
    assert issubclass(avsplat.FileError, OSError)
    assert avsplat.FileError.__name__ == "FileError"
    assert avsplat.IOError is avsplat.FileError
    assert avsplat.io.IOError is avsplat.FileError
    bad = tmp_path / "not_a_scene.ply"
    bad.write_text("hello\n")
    with pytest.raises(avsplat.FileError, match="not_a_scene.ply"):
        avsplat.read_ply(str(bad))


def test_importing_avsplat_leaves_dask_and_matplotlib_unloaded():
    code = "import sys, avsplat; print('dask' in sys.modules, 'matplotlib' in sys.modules, 'open3d' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False", "False"]


def test_unknown_attribute_raises_attributeerror():
    with pytest.raises(AttributeError, match="no_such_name"):
        avsplat.no_such_name  # noqa: B018


def test_render_is_the_module_and_calls_as_the_function():
    import avsplat.render as render_module

    assert render_module is avsplat.render
    assert avsplat.render.RenderWorkspace is avsplat.RenderWorkspace
    pred = avsplat.simulate_predictions(views=6, width=32, height=24, seed=0)
    cloud = avsplat.fuse_gaussians(pred.gaussians(), 0.05).cloud
    camera = pred.target_cameras[0]
    a = avsplat.render(cloud, camera, background=(0.1, 0.2, 0.3))
    b = avsplat.render.render(cloud, camera, background=(0.1, 0.2, 0.3))
    np.testing.assert_array_equal(a.color, b.color)
    assert a.color.shape == (24, 32, 3) and a.alpha.max() > 0
