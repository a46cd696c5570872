"""Image and geometry metrics (C++ module ``metrics``): PSNR and SSIM as the 3DGS evaluation
code computes them; Chamfer distance, accuracy/completeness and statistical outlier removal on
point sets."""

from ._avsplat import (
    AccuracyCompleteness,
    accuracy_completeness,
    chamfer_distance,
    compute_point_cloud_distance,
    psnr,
    remove_statistical_outliers,
    ssim,
)

__all__ = ["AccuracyCompleteness", "accuracy_completeness", "chamfer_distance", "compute_point_cloud_distance",
           "psnr", "remove_statistical_outliers", "ssim"]
