"""Registration and stitching (C++ module ``registration``): chunks of a long capture aligned by
the frames they share (robust Umeyama per pair, a pose graph over similarities), moved into one
frame and fused."""

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

__all__ = ["ChunkAlignment", "PairAlignment", "PredictionChunk", "Similarity",
           "SimilarityFit", "StitchResult", "align_chunks", "fuse_chunks", "read_prediction_chunk",
           "similarity_from_correspondences", "stitch"]
