"""Voxel fusion of per-pixel predictions (C++ module ``fusion``).

``SparseVoxelGrid`` groups samples by voxel; ``fuse_voxels`` fuses raw feature vectors and
``fuse_gaussians`` fuses Gaussians, with the ``mean``, ``softmax`` (AnySplat) or ``occupancy``
(AVSplat) policy; ``FusionStream`` fuses inputs larger than memory; ``decode_gaussians`` /
``encode_gaussians`` turn raw head features into Gaussians and back. ``fusion_knobs()`` lists
every knob with its default, range and meaning.
"""

from ._avsplat import (
    FeatureFusionResult,
    FeatureLayout,
    FusionStream,
    GaussianFusionResult,
    SparseVoxelGrid,
    decode_gaussians,
    encode_gaussians,
    fuse_gaussians,
    fuse_voxels,
    fusion_knobs,
)

__all__ = ["FeatureFusionResult", "FeatureLayout", "FusionStream", "GaussianFusionResult", "SparseVoxelGrid",
           "decode_gaussians", "encode_gaussians", "fuse_gaussians", "fuse_voxels", "fusion_knobs"]
