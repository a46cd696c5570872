"""Reading and writing scenes, cameras and images (C++ module ``io``).

Gaussian files: 3DGS PLY, PlayCanvas compressed PLY, SPZ, SOG (versions 1 and 2), PlayCanvas LOD
sets (``lod-meta.json``: ``read_lod_set``, ``write_lod_set``), ``.splat``, glTF binary (``.glb``,
KHR_gaussian_splatting) and ``.ksplat`` (read); ``read_gaussians``
detects the format from the content and ``write_gaussians`` chooses it from the name. Cameras:
avsplat's JSON, 3DGS ``cameras.json`` and nerfstudio ``transforms.json``, COLMAP models (``read_colmap_cameras``). Images: PNG. Every
writer replaces its file atomically. Errors are :class:`FileError` (a subclass of OSError).
"""

from ._avsplat import (
    FileError,
    GaussianFormatInfo,
    GaussianPlyWriter,
    LodSetInfo,
    detect_gaussian_format,
    read_camera_json,
    read_cameras_json,
    read_colmap_cameras,
    read_compressed_ply,
    read_gaussians,
    read_glb,
    read_ksplat,
    read_lod_set,
    read_lod_set_info,
    read_ply,
    read_ply_data,
    read_sog,
    read_splat,
    read_spz,
    read_spz_header,
    turbo_colormap,
    write_alpha_png,
    write_camera_json,
    write_cameras_json,
    write_color_png,
    write_compressed_ply,
    write_depth_png,
    write_gaussians,
    write_glb,
    write_lod_set,
    write_ply,
    write_sog,
    write_splat,
    write_spz,
)

# The former name of FileError, which shadowed Python's builtin IOError on `import *`; kept as an
# alias for one release and left out of __all__.
IOError = FileError  # noqa: A001

__all__ = ["FileError", "GaussianFormatInfo", "GaussianPlyWriter", "LodSetInfo", "detect_gaussian_format", "read_camera_json",
           "read_cameras_json", "read_colmap_cameras", "read_compressed_ply", "read_gaussians", "read_glb", "read_ksplat",
           "read_lod_set", "read_lod_set_info", "read_ply", "read_ply_data", "read_sog",
           "read_splat", "read_spz", "read_spz_header", "turbo_colormap", "write_alpha_png", "write_camera_json",
           "write_cameras_json", "write_color_png", "write_compressed_ply", "write_depth_png", "write_gaussians",
           "write_glb", "write_lod_set", "write_ply", "write_sog", "write_splat", "write_spz"]
