"""GaussianCloud <-> Open3D point clouds (C++ target ``avsplat::open3d``); Open3D is imported
only when a conversion runs."""

from .open3d_adapter import from_open3d, to_open3d, to_open3d_legacy

__all__ = ["from_open3d", "to_open3d", "to_open3d_legacy"]
