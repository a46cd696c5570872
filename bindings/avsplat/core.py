"""The data model (C++ module ``core``): Gaussian clouds, cameras and their framing, SH helpers,
transforms."""

from ._avsplat import (
    Camera,
    DeviceError,
    GaussianCloud,
    SanitizeReport,
    concatenate,
    coordinate_system_change,
    default_camera,
    defaults,
    morton_order,
    orbit_cameras,
    robust_bounds,
    sh_degree_for_coeffs,
    sh_rotation,
    transform,
)

__all__ = ["Camera", "DeviceError", "GaussianCloud", "SanitizeReport", "concatenate", "coordinate_system_change",
           "default_camera", "defaults", "morton_order", "orbit_cameras", "robust_bounds", "sh_degree_for_coeffs", "sh_rotation", "transform"]
