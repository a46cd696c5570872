"""The data model (C++ module ``core``): Gaussian clouds, cameras, SH helpers, transforms."""

from ._avsplat import (
    Camera,
    DeviceError,
    GaussianCloud,
    SanitizeReport,
    concatenate,
    coordinate_system_change,
    defaults,
    morton_order,
    sh_degree_for_coeffs,
    sh_rotation,
    transform,
)

__all__ = ["Camera", "DeviceError", "GaussianCloud", "SanitizeReport", "concatenate", "coordinate_system_change",
           "defaults", "morton_order", "sh_degree_for_coeffs", "sh_rotation", "transform"]
