"""The splat renderer (C++ module ``render``): CPU reference and CUDA back end.

``render(cloud, camera)`` returns colour, alpha, depth and contributor counts; a
``RenderWorkspace`` keeps buffers between renders of the same size.
"""

from ._avsplat import RenderResult, RenderStats, RenderWorkspace, cuda_device_count, render

__all__ = ["RenderResult", "RenderStats", "RenderWorkspace", "cuda_device_count", "render"]
