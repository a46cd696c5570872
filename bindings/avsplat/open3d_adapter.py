"""GaussianCloud <-> Open3D point clouds, in Python (mirrors avsplat/open3d.h).

Open3D's Python module is a separate binary from avsplat's, so the conversion goes through
numpy: one copy each way. A tensor point cloud holds the Gaussians in one of two layouts:

``"ply"`` (the default of ``to_open3d``): one {N, 1} attribute per property of the INRIA 3DGS
    PLY file, with the file's encodings: ``f_dc_0..2``, ``f_rest_0..`` (channel-major: all
    coefficients of red, then green, then blue), ``opacity`` (logit), ``scale_0..2`` (log),
    ``rot_0..3`` (w, x, y, z). It is what ``open3d.t.io.read_point_cloud`` returns for a 3DGS
    PLY file and what ``open3d.t.io.write_point_cloud`` writes back to one (Open3D's PLY writer
    takes only {N, 1} attributes besides positions, normals and colours).
``"packed"``: the attribute names of Open3D's own Gaussian-splat support (avsplat/open3d.h):
    positions {N,3} Float32, scale {N,3} linear, rot {N,4} (w,x,y,z), opacity {N,1} logit,
    f_dc {N,3}, f_rest {N,K-1,3} (only when the SH degree is > 0).

Both carry confidence {N,1} when present, and each extra channel under its own name as {N,1}.
``from_open3d`` reads either. The legacy point cloud is a preview: points and colours from SH
degree 0 (0.5 + C0 f_dc, clamped to [0, 1]).
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
_LAYOUTS = ("ply", "packed")


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


def to_open3d(cloud: GaussianCloud, layout: str = "ply") -> open3d.t.geometry.PointCloud:
    """Convert a GaussianCloud to an Open3D tensor point cloud.

    Parameters
    ----------
    cloud : GaussianCloud
        N Gaussians; validated first.
    layout : {"ply", "packed"}
        ``"ply"``: one {N, 1} attribute per 3DGS PLY property, encoded as in the file
        (``f_dc_0..2``, ``f_rest_i`` channel-major, ``opacity`` logit, ``scale_0..2`` log,
        ``rot_0..3``), which ``open3d.t.io.write_point_cloud`` writes as a 3DGS PLY file and
        ``open3d.t.io.read_point_cloud`` reads back. ``"packed"``: Open3D's Gaussian-splat
        attribute names, as the C++ adapter (avsplat/open3d.h).

    Returns
    -------
    open3d.t.geometry.PointCloud
        On the CPU, all float32. ``"packed"``: ``positions`` {N, 3}, ``scale`` {N, 3}
        (linear), ``rot`` {N, 4} (w, x, y, z), ``opacity`` {N, 1} (logit), ``f_dc`` {N, 3} and,
        for SH degree > 0, ``f_rest`` {N, K - 1, 3}. Both layouts add ``confidence`` and the
        extra channels as {N, 1}.

    Raises
    ------
    ValueError
        If the cloud is invalid (naming the field and the first bad index), or for an unknown
        layout.
    """
    if layout not in _LAYOUTS:
        raise ValueError(f"to_open3d: layout must be one of {', '.join(_LAYOUTS)}, got {layout!r}")
    o3d = _o3d()
    cloud.validate()
    t = lambda a: o3d.core.Tensor(np.ascontiguousarray(a, dtype=np.float32))  # noqa: E731
    pcd = o3d.t.geometry.PointCloud()
    pcd.point.positions = t(cloud.means)
    opacity = _logit(cloud.opacities)[:, None]
    if layout == "packed":
        pcd.point["scale"] = t(cloud.scales)
        pcd.point["rot"] = t(cloud.rotations)
        pcd.point["opacity"] = t(opacity)
        pcd.point["f_dc"] = t(cloud.sh[:, 0, :])
        if cloud.sh_degree > 0:
            pcd.point["f_rest"] = t(cloud.sh[:, 1:, :])
    else:
        for c in range(3):
            pcd.point[f"f_dc_{c}"] = t(cloud.sh[:, 0, c:c + 1])
        rest = cloud.sh[:, 1:, :]
        for c in range(3):  # channel-major, as the 3DGS PLY file
            for k in range(rest.shape[1]):
                pcd.point[f"f_rest_{c * rest.shape[1] + k}"] = t(rest[:, k, c:c + 1])
        pcd.point["opacity"] = t(opacity)
        with np.errstate(divide="ignore"):  # a zero scale is -inf in the file, as the PLY writer's
            log_scales = np.log(cloud.scales.astype(np.float64))
        for a in range(3):
            pcd.point[f"scale_{a}"] = t(log_scales[:, a:a + 1])
        for a in range(4):
            pcd.point[f"rot_{a}"] = t(cloud.rotations[:, a:a + 1])
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


def _columns(pcd: open3d.t.geometry.PointCloud, prefix: str, count: int, n: int) -> npt.NDArray[np.float32]:
    """(n, count) from the {N, 1} attributes prefix0 .. prefix{count-1}."""
    return np.concatenate([_attr(pcd, f"{prefix}{i}", 1, n) for i in range(count)], axis=1)


def _sh_ply(pcd: open3d.t.geometry.PointCloud, n: int) -> npt.NDArray[np.float32]:
    rest = 0
    while f"f_rest_{rest}" in pcd.point:
        rest += 1
    if rest % 3 or rest // 3 + 1 not in (1, 4, 9, 16):
        raise ValueError(f"from_open3d: {rest} attributes f_rest_0 .. f_rest_{rest - 1}, expected 0, 9, 24 or 45 "
                         "(3 (K - 1) with K in 4, 9, 16)")
    k = rest // 3 + 1
    sh = np.zeros((n, k, 3), np.float32)
    sh[:, 0, :] = _columns(pcd, "f_dc_", 3, n)
    if k > 1:
        sh[:, 1:, :] = _columns(pcd, "f_rest_", rest, n).reshape(n, 3, k - 1).transpose(0, 2, 1)
    return sh


def _sh_packed(pcd: open3d.t.geometry.PointCloud, n: int) -> npt.NDArray[np.float32]:
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
    return sh


def from_open3d(pcd: open3d.t.geometry.PointCloud, extra_keys: Iterable[str] | None = None) -> GaussianCloud:
    """Convert an Open3D tensor point cloud with Gaussian-splat attributes to a GaussianCloud.

    Parameters
    ----------
    pcd : open3d.t.geometry.PointCloud
        ``positions`` {N, 3} and the Gaussians in either layout (see ``to_open3d``): the 3DGS
        PLY properties as {N, 1} attributes (what ``open3d.t.io.read_point_cloud`` returns for
        a 3DGS PLY file: ``f_dc_0..2``, optional ``f_rest_0..``, ``opacity``, ``scale_0..2``,
        ``rot_0..3``), or Open3D's packed names (``scale`` {N, 3} linear, ``rot`` {N, 4},
        ``opacity`` {N, 1} logit, ``f_dc`` {N, 3}, optional ``f_rest`` {N, K - 1, 3} with K in
        4, 9, 16). The packed layout is used when ``f_dc`` is present.
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
    if "f_dc" in pcd.point:
        sh = _sh_packed(pcd, n)
        scales = _attr(pcd, "scale", 3, n)
        rotations = _attr(pcd, "rot", 4, n)
    elif "f_dc_0" in pcd.point:
        sh = _sh_ply(pcd, n)
        scales = np.exp(_columns(pcd, "scale_", 3, n).astype(np.float64)).astype(np.float32)
        rotations = _columns(pcd, "rot_", 4, n)
    else:
        raise ValueError("from_open3d: missing point attribute 'f_dc' (packed layout) or 'f_dc_0' (3DGS PLY layout)")
    opacity = 1.0 / (1.0 + np.exp(-_attr(pcd, "opacity", 1, n)[:, 0].astype(np.float64)))
    confidence: npt.NDArray[np.float32] | None = None
    extras: dict[str, npt.NDArray[np.float32]] = {}
    for key in extra_keys or ():
        values = _attr(pcd, key, 1, n)[:, 0]
        if key == "confidence":
            confidence = values
        else:
            extras[key] = values
    cloud = GaussianCloud(_attr(pcd, "positions", 3, n), scales, rotations, opacity, sh, confidence=confidence)
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
