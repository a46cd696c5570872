"""avsplat: the geometry side of feed-forward 3D Gaussian Splatting.

Fuse per-pixel Gaussian predictions with occupancy-guided voxel fusion, render them, measure
them and export them. The names mirror the C++ API (``avsplat::GaussianCloud`` ->
``avsplat.GaussianCloud``); arrays go in and out as numpy float32 with the shapes given in each
docstring.
"""

from ._avsplat import (  # noqa: F401
    Camera,
    DeviceError,
    GaussianCloud,
    IOError,
    SanitizeReport,
    concatenate,
    read_camera_json,
    read_cameras_json,
    read_ply,
    sh_degree_for_coeffs,
    write_camera_json,
    write_cameras_json,
    write_ply,
)

__version__ = "0.1.0"
