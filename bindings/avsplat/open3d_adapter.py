"""GaussianCloud <-> Open3D point clouds, in Python (mirrors avsplat/open3d.h).

Open3D's Python module is a separate binary from avsplat's, so the conversion goes through
numpy: one copy each way. The tensor point cloud uses the attribute names of Open3D's own
Gaussian-splat support:

    positions {N,3} Float32, scale {N,3} linear, rot {N,4} (w,x,y,z), opacity {N,1} logit,
    f_dc {N,3}, f_rest {N,K-1,3} (only when the SH degree is > 0),
    confidence {N,1} when present, and each extra channel under its own name as {N,1}.

The legacy point cloud is a preview: points and colours from SH degree 0 (0.5 + C0 f_dc,
clamped to [0, 1]).
"""

from __future__ import annotations

from types import ModuleType
from typing import TYPE_CHECKING, Any, Iterable

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    import open3d

    from .core import GaussianCloud

SH_C0 = 0.28209479177387814
_GAUSSIAN_KEYS = ("positions", "scale", "rot", "opacity", "f_dc", "f_rest")


def _o3d() -> ModuleType:
    try:
        import open3d
    except ImportError as e:  # pragma: no cover - depends on the machine
        raise ImportError("the Open3D adapter needs open3d (Debian: python3-open3d)") from e
    return open3d


def _logit(p: npt.NDArray[np.floating[Any]]) -> npt.NDArray[np.float32]:
    p = p.astype(np.float64)
    with np.errstate(divide="ignore"):
        return (np.log(p) - np.log1p(-p)).astype(np.float32)


def to_open3d(cloud: GaussianCloud) -> open3d.t.geometry.PointCloud:
    """Convert a GaussianCloud to an Open3D tensor point cloud.

    Parameters
    ----------
    cloud : GaussianCloud
        N Gaussians; validated first.

    Returns
    -------
    open3d.t.geometry.PointCloud
        On the CPU, with Open3D's Gaussian-splat attribute names: ``positions`` {N, 3},
        ``scale`` {N, 3} (linear), ``rot`` {N, 4} (w, x, y, z), ``opacity`` {N, 1} (logit),
        ``f_dc`` {N, 3} and, for SH degree > 0, ``f_rest`` {N, K - 1, 3}; all float32.

    Raises
    ------
    ValueError
        If the cloud is invalid (naming the field and the first bad index).
    """
    o3d = _o3d()
    cloud.validate()
    t = lambda a: o3d.core.Tensor(np.ascontiguousarray(a, dtype=np.float32))  # noqa: E731
    pcd = o3d.t.geometry.PointCloud()
    pcd.point.positions = t(cloud.means)
    pcd.point["scale"] = t(cloud.scales)
    pcd.point["rot"] = t(cloud.rotations)
    pcd.point["opacity"] = t(_logit(cloud.opacities)[:, None])
    pcd.point["f_dc"] = t(cloud.sh[:, 0, :])
    if cloud.sh_degree > 0:
        pcd.point["f_rest"] = t(cloud.sh[:, 1:, :])
    if cloud.confidence is not None:
        pcd.point["confidence"] = t(cloud.confidence[:, None])
    for name, values in cloud.extras.items():
        pcd.point[name] = t(values[:, None])
    return pcd


def _attr(pcd: open3d.t.geometry.PointCloud, key: str, per_point: int, n: int) -> npt.NDArray[np.float32]:
    if key not in pcd.point:
        raise ValueError(f"from_open3d: missing point attribute '{key}'")
    a = pcd.point[key].cpu().numpy()
    if a.shape[0] != n or a.size != n * per_point:
        raise ValueError(f"from_open3d: attribute '{key}' has shape {tuple(a.shape)}, "
                         f"expected {n} x {per_point} values")
    return a.reshape(n, per_point).astype(np.float32)


def from_open3d(pcd: open3d.t.geometry.PointCloud, extra_keys: Iterable[str] | None = None) -> GaussianCloud:
    """Convert an Open3D tensor point cloud with Gaussian-splat attributes to a GaussianCloud.

    Parameters
    ----------
    pcd : open3d.t.geometry.PointCloud
        With ``positions`` {N, 3}, ``scale`` {N, 3}, ``rot`` {N, 4}, ``opacity`` {N, 1} (logit)
        and ``f_dc`` {N, 3}; ``f_rest`` {N, K - 1, 3} (K in 4, 9, 16) is optional.
    extra_keys : list of str, optional
        Further {N} or {N, 1} attributes to keep as extra channels (``"confidence"`` becomes the
        confidence). Open3D's Python API cannot list attribute names, so they must be named.

    Returns
    -------
    GaussianCloud
        N Gaussians, float32.

    Raises
    ------
    ValueError
        If an attribute is missing or malformed (naming it).
    """
    from . import GaussianCloud

    if "positions" not in pcd.point:
        raise ValueError("from_open3d: missing point attribute 'positions'")
    n = int(pcd.point.positions.shape[0])
    k = 1
    if "f_rest" in pcd.point:
        rest = pcd.point["f_rest"].cpu().numpy()
        per = rest.size // max(n, 1)
        if rest.shape[0] != n or per % 3 or per // 3 + 1 not in (4, 9, 16):
            raise ValueError(f"from_open3d: attribute 'f_rest' has shape {tuple(rest.shape)}, "
                             "expected {N, K-1, 3} with K in 4, 9, 16")
        k = per // 3 + 1
    sh = np.zeros((n, k, 3), np.float32)
    sh[:, 0, :] = _attr(pcd, "f_dc", 3, n)
    if k > 1:
        sh[:, 1:, :] = _attr(pcd, "f_rest", (k - 1) * 3, n).reshape(n, k - 1, 3)
    opacity = 1.0 / (1.0 + np.exp(-_attr(pcd, "opacity", 1, n)[:, 0].astype(np.float64)))
    confidence: npt.NDArray[np.float32] | None = None
    extras: dict[str, npt.NDArray[np.float32]] = {}
    for key in extra_keys or ():
        values = _attr(pcd, key, 1, n)[:, 0]
        if key == "confidence":
            confidence = values
        else:
            extras[key] = values
    cloud = GaussianCloud(_attr(pcd, "positions", 3, n), _attr(pcd, "scale", 3, n),
                          _attr(pcd, "rot", 4, n), opacity, sh, confidence=confidence)
    for key, values in extras.items():
        cloud.set_extra(key, values)
    return cloud


def to_open3d_legacy(cloud: GaussianCloud) -> open3d.geometry.PointCloud:
    """Convert a GaussianCloud to a legacy Open3D point cloud, for a preview.

    Parameters
    ----------
    cloud : GaussianCloud
        N Gaussians.

    Returns
    -------
    open3d.geometry.PointCloud
        N points (the means, float64) with colours from the SH degree-0 coefficients, clipped
        to [0, 1].
    """
    o3d = _o3d()
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(cloud.means.astype(np.float64))
    colors = np.clip(0.5 + SH_C0 * cloud.sh[:, 0, :].astype(np.float64), 0.0, 1.0)
    pcd.colors = o3d.utility.Vector3dVector(colors)
    return pcd
