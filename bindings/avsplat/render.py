"""The splat renderer (C++ module ``render``): CPU reference and CUDA back end.

``render(cloud, camera)`` returns colour, alpha, depth and contributor counts; a
``RenderWorkspace`` keeps buffers between renders of the same size.

This module is also callable: ``avsplat.render(cloud, camera, ...)`` is
``avsplat.render.render(cloud, camera, ...)``, so the function keeps its top-level name while
the module holds the renderer's other names.
"""

import sys
import types
from typing import Any

from ._avsplat import RenderResult, RenderStats, RenderWorkspace, cuda_device_count, render

__all__ = ["RenderResult", "RenderStats", "RenderWorkspace", "cuda_device_count", "render"]


class _CallableModule(types.ModuleType):
    def __call__(self, *args: Any, **kwargs: Any) -> RenderResult:
        return render(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
