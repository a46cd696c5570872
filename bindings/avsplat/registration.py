"""Registration and stitching (C++ module ``registration``): chunks of a long capture aligned by
the frames they share (robust Umeyama per pair, a pose graph over similarities), moved into one
frame and fused; Gaussian sets without shared frames registered with Open3D
(:func:`register_gaussians`)."""

from ._avsplat import (
    ChunkAlignment,
    PairAlignment,
    PredictionChunk,
    Similarity,
    SimilarityFit,
    StitchResult,
    align_chunks,
    fuse_chunks,
    read_prediction_chunk,
    similarity_from_correspondences,
    stitch,
)
from .gaussian_registration import GaussianRegistration, register_gaussians

__all__ = ["ChunkAlignment", "GaussianRegistration", "PairAlignment", "PredictionChunk", "Similarity",
           "SimilarityFit", "StitchResult", "align_chunks", "fuse_chunks", "read_prediction_chunk",
           "register_gaussians", "similarity_from_correspondences", "stitch"]
