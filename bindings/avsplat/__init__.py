"""avsplat: the geometry side of feed-forward 3D Gaussian Splatting.

Fuse per-pixel Gaussian predictions with occupancy-guided voxel fusion, render them, measure
them, reduce them and export them. The names mirror the C++ API (``avsplat::GaussianCloud`` ->
``avsplat.GaussianCloud``); arrays go in and out as numpy float32 with the shapes given in each
docstring.

The subpackages mirror the C++ modules, as Open3D's do:

    avsplat.core        GaussianCloud, Camera, transforms
    avsplat.io          read and write scenes, cameras, images
    avsplat.fusion      SparseVoxelGrid, fuse_voxels, fuse_gaussians, FusionStream
    avsplat.render      render, RenderWorkspace
    avsplat.metrics     psnr, ssim, chamfer_distance, ...
    avsplat.point_maps  gaussians_from_point_maps
    avsplat.predictions read_prediction_npz (the prediction .npz layout)
    avsplat.registration align_chunks, stitch (chunked captures)
    avsplat.reduce      prune, reduce_sh, simplify, build_lod
    avsplat.assist      Assist-View selection, view coverage
    avsplat.view        the web viewer: show, write_html (avsplat view / convert to .html)
    avsplat.open3d      to_open3d, from_open3d
    avsplat.dask        fusion on a Dask cluster
    avsplat.sim         the prediction simulator (a layer on top of the product)
    avsplat.eval        the evaluation reports

The main names are also here at the top level (``avsplat.__all__``); every other public name of
the subpackages resolves here too, as it always has.
"""

import os as _os
import sys as _sys

# OpenMP threads sleep when idle unless the user chose otherwise: libgomp's default spins a
# waiting thread before it sleeps, taking CPU from other processes between parallel regions.
# libgomp reads the variable when it is loaded, which is when _avsplat is imported below (unless
# another module loaded it before avsplat was imported).
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


from . import assist, core, fusion, io, metrics, point_maps, predictions, reduce, registration, render, sim, view
from . import open3d  # noqa: F401  (imports Open3D only when a conversion runs)
from .assist import *  # noqa: F401,F403
from .core import *  # noqa: F401,F403
from .fusion import *  # noqa: F401,F403
from .io import *  # noqa: F401,F403
from .metrics import *  # noqa: F401,F403
from .open3d import *  # noqa: F401,F403
from .point_maps import *  # noqa: F401,F403
from .predictions import *  # noqa: F401,F403
from .reduce import *  # noqa: F401,F403
from .registration import *  # noqa: F401,F403
from .render import *  # noqa: F401,F403
from .sim import *  # noqa: F401,F403
from .view import *  # noqa: F401,F403

# avsplat.render is the module, which calls as the function always did (render.py); the star
# import above bound the name to the function.
render = _sys.modules[__name__ + ".render"]  # noqa: F811

# The former name of FileError (deprecated; it shadowed Python's builtin IOError on `import *`).
from .io import IOError  # noqa: F401,A004

# CMake's project(VERSION), compiled into the module: one number for the CLI, Python and CMake.
from ._avsplat import __version__  # noqa: E402,F401

# GaussianCloud.to_open3d() and friends, as the C++ free functions are in Python.
setattr(GaussianCloud, "to_open3d", to_open3d)
setattr(GaussianCloud, "to_open3d_legacy", to_open3d_legacy)
setattr(GaussianCloud, "from_open3d", staticmethod(from_open3d))

# The product's main names: the data model, reading and writing, fusion, rendering, metrics and
# reduction. The simulator's, the reports' and the helpers' names stay in their subpackages.
__all__ = [
    # data model
    "Camera", "DeviceError", "FileError", "GaussianCloud", "concatenate", "transform", "default_camera", "orbit_cameras",
    # read and write
    "read_gaussians", "write_gaussians", "read_ply", "write_ply", "read_compressed_ply", "write_compressed_ply",
    "read_spz", "write_spz", "read_sog", "write_sog", "read_lod_set", "write_lod_set", "read_splat", "write_splat", "read_camera_json",
    "write_camera_json", "read_cameras_json", "write_cameras_json", "read_colmap_cameras", "GaussianPlyWriter",
    # fusion
    "SparseVoxelGrid", "FusionStream", "fuse_voxels", "fuse_gaussians", "decode_gaussians",
    "gaussians_from_point_maps", "read_prediction_npz",
    # rendering
    "render", "RenderWorkspace",
    # metrics
    "psnr", "ssim", "chamfer_distance",
    # reduction
    "prune", "reduce_sh", "simplify", "build_lod",
    # viewing
    "show", "write_html",
    # registration and stitching
    "Similarity", "PredictionChunk", "align_chunks", "stitch",
]


def __getattr__(name: str):
    # avsplat.dask, avsplat.eval, avsplat.evaluation and avsplat.plotting import heavier
    # packages (dask, matplotlib): loaded on first use.
    if name in ("dask", "eval", "evaluation", "plotting"):
        import importlib

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module 'avsplat' has no attribute '{name}'")
