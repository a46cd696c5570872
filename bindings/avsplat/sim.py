"""The prediction simulator (C++ target ``avsplat::sim``): a scene with known ground truth, views
of it, and predictions with the errors real feed-forward models make. A layer on top of the
product, used by the demo, the reports and the tests."""

from ._avsplat import (
    CaptureChunk,
    ChunkedCapture,
    GroundTruthImage,
    Predictions,
    SceneObject,
    bunny_mesh,
    ground_truth,
    input_cameras,
    scene_color,
    simulate_chunked_capture,
    simulate_predictions,
    target_cameras,
)

__all__ = ["CaptureChunk", "ChunkedCapture", "GroundTruthImage", "Predictions", "SceneObject", "bunny_mesh", "ground_truth", "input_cameras",
           "scene_color", "simulate_chunked_capture", "simulate_predictions", "target_cameras"]
