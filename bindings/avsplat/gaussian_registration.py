"""Registration of two Gaussian sets that share no frames (two captures of one place, or a
prediction against an existing scene) with Open3D's pipelines: FPFH features matched by RANSAC
with scale estimation, then point-to-point ICP with scale, point-to-plane ICP and coloured ICP
(with the SH DC colour). Open3D is imported only when a registration runs."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ._avsplat import Similarity, transform

if TYPE_CHECKING:
    import open3d

    from .core import GaussianCloud

SH_C0 = 0.28209479177387814
# FPFH radius in voxels: wide enough that a feature sees beyond one plane (ground, wall).
_FEATURE_RADIUS = 10.0


@dataclass
class GaussianRegistration:
    """The result of :func:`register_gaussians`.

    Attributes
    ----------
    transform : Similarity
        Maps the source's coordinates into the target's.
    fitness : float
        Fraction of the (opacity-filtered, downsampled) source points with a target point within
        ``max_correspondence_distance`` after the final refinement (Open3D's fitness).
    inlier_rmse : float
        RMS distance of those inlier pairs, in the target's units (Open3D's inlier_rmse).
    ransac_fitness : float
        The fitness of the global (FPFH + RANSAC) stage alone.
    """

    transform: Similarity
    fitness: float
    inlier_rmse: float
    ransac_fitness: float

    def __repr__(self) -> str:
        return (f"GaussianRegistration({self.transform!r}, fitness={self.fitness:.3f}, "
                f"inlier_rmse={self.inlier_rmse:.4g})")


def _point_cloud(o3d: Any, cloud: GaussianCloud, min_opacity: float, voxel: float) -> open3d.geometry.PointCloud:
    means = np.asarray(cloud.means, dtype=np.float64)
    keep = np.asarray(cloud.opacities) >= min_opacity
    if not np.any(keep):
        raise ValueError(f"register_gaussians: no Gaussian has opacity >= min_opacity ({min_opacity})")
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(means[keep]))
    dc = np.asarray(cloud.sh, dtype=np.float64)[keep, 0, :]
    pc.colors = o3d.utility.Vector3dVector(np.clip(0.5 + SH_C0 * dc, 0.0, 1.0))
    return pc.voxel_down_sample(voxel)


def _similarity(m: npt.NDArray[np.float64]) -> Similarity:
    a = m[:3, :3]
    scale = float(np.cbrt(np.linalg.det(a)))
    u, _, vt = np.linalg.svd(a / scale)
    return Similarity(u @ vt, m[:3, 3], scale)


def register_gaussians(source: GaussianCloud, target: GaussianCloud, voxel_size: float | None = None, *,
                       min_opacity: float = 0.1, with_scale: bool = True, colored: bool = True,
                       ransac_iterations: int = 100000, restarts: int = 4, seed: int = 0) -> GaussianRegistration:
    """Find the similarity that maps `source` onto `target` without shared frames.

    The Gaussians' means with opacity >= `min_opacity` (opacity decides which Gaussians take
    part; Open3D's pipelines weigh every point alike), downsampled on a voxel grid, get normals
    and FPFH features (radii 2 and 5 voxels); RANSAC over feature matches (Open3D's
    ``registration_ransac_based_on_feature_matching``, point-to-point estimation with scale,
    edge-length and distance checkers) gives the global estimate, which point-to-point ICP with
    scale, then point-to-plane ICP and (with `colored`) coloured ICP on the DC colour
    0.5 + C0 f_dc refine. The FPFH features are not scale invariant: the two sets must have
    the source is first brought to the target's size by the ratio of their RMS spreads, a prior
    that holds when the two sets cover comparable parts of the scene.

    Parameters
    ----------
    source, target : GaussianCloud
    voxel_size : float, optional
        Downsampling voxel in the target's units; None: 1 / 40 of the target's bounding-box
        diagonal. The source is downsampled at the same size (in its own units).
    min_opacity : float
        Gaussians below it are left out.
    with_scale : bool
        False: a rigid transform (scale 1).
    colored : bool
        Refine with coloured ICP last.
    ransac_iterations : int
        RANSAC's maximum iterations per run.
    restarts : int
        RANSAC runs (>= 1); the one whose coarse ICP refinement fits best is kept.
    seed : int
        Open3D's random seed of the first run (``open3d.utility.random.seed``); run k uses
        seed + k, for a repeatable result.

    Returns
    -------
    GaussianRegistration

    Raises
    ------
    ValueError
        For a set with no Gaussian above `min_opacity`, a voxel size that is not > 0, or too few
        points left to register (fewer than 10 after downsampling).
    """
    from .open3d_adapter import _o3d

    o3d = _o3d()
    reg = o3d.pipelines.registration
    if voxel_size is None:
        means = np.asarray(target.means, dtype=np.float64)
        if len(means) == 0:
            raise ValueError("register_gaussians: the target has no Gaussians")
        voxel_size = float(np.linalg.norm(means.max(axis=0) - means.min(axis=0))) / 40.0
    if not (np.isfinite(voxel_size) and voxel_size > 0):
        raise ValueError(f"register_gaussians: voxel_size must be finite and > 0, got {voxel_size}")
    if restarts < 1:
        raise ValueError(f"register_gaussians: restarts must be >= 1, got {restarts}")
    # FPFH features and RANSAC's edge-length check are not scale invariant: the source is first
    # brought to the target's size by the ratio of their RMS spreads (a prior the later stages
    # refine), so that sets at any relative scale match.
    prior = 1.0
    if with_scale:
        spread = [float(np.sqrt(((m - m.mean(axis=0)) ** 2).sum(axis=1).mean()))
                  for m in (np.asarray(source.means, dtype=np.float64), np.asarray(target.means, dtype=np.float64))]
        if spread[0] > 0 and spread[1] > 0:
            prior = spread[1] / spread[0]
            source = transform(source, None, None, prior)
    src = _point_cloud(o3d, source, min_opacity, voxel_size)
    dst = _point_cloud(o3d, target, min_opacity, voxel_size)
    for name, pc in (("source", src), ("target", dst)):
        if len(pc.points) < 10:
            raise ValueError(f"register_gaussians: the {name} has {len(pc.points)} points after downsampling "
                             f"(at least 10 are needed); lower voxel_size or min_opacity")
    features = []
    for pc in (src, dst):
        pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel_size, max_nn=30))
        features.append(reg.compute_fpfh_feature(pc, o3d.geometry.KDTreeSearchParamHybrid(radius=_FEATURE_RADIUS * voxel_size,
                                                                                         max_nn=200)))
    distance = 1.5 * voxel_size
    criteria = reg.ICPConvergenceCriteria(relative_fitness=1e-9, relative_rmse=1e-9, max_iteration=300)
    # Planes (ground, walls) make FPFH matches ambiguous, so one RANSAC run can settle on a
    # mirrored or rotated solution: each of `restarts` runs (seeds seed, seed + 1, ...) is refined
    # by a coarse scaled ICP and the one with the highest fitness (then lowest RMSE) is kept.
    best: tuple[float, float] | None = None
    ransac_fitness = 0.0
    m = np.eye(4)
    for k in range(restarts):
        if hasattr(o3d.utility, "random"):
            o3d.utility.random.seed(seed + k)
        ransac = reg.registration_ransac_based_on_feature_matching(
            src, dst, features[0], features[1], False, distance,
            reg.TransformationEstimationPointToPoint(with_scale), 3,
            [reg.CorrespondenceCheckerBasedOnEdgeLength(0.8), reg.CorrespondenceCheckerBasedOnDistance(distance)],
            reg.RANSACConvergenceCriteria(ransac_iterations, 0.9999))
        coarse = reg.registration_icp(src, dst, voxel_size, ransac.transformation,
                                      reg.TransformationEstimationPointToPoint(with_scale), criteria)
        score = (coarse.fitness, -coarse.inlier_rmse)
        if best is None or score > best:
            best, m, ransac_fitness = score, np.asarray(coarse.transformation), float(ransac.fitness)
    # The refinements run on denser clouds (a third of the voxel) with a tight distance: where the
    # overlap ends, source points find their nearest target point on its border, which pulls a
    # scaled fit inwards by about the distance threshold; a tight threshold keeps that bias small.
    src = _point_cloud(o3d, source, min_opacity, voxel_size / 3)
    dst = _point_cloud(o3d, target, min_opacity, voxel_size / 3)
    dst.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel_size, max_nn=30))
    for refine in (voxel_size, voxel_size / 2):
        m = np.asarray(reg.registration_icp(src, dst, refine, m, reg.TransformationEstimationPointToPoint(with_scale),
                                            criteria).transformation)
    # The rigid refinements run on the source scaled by the estimate, so that they keep it.
    scaled = _similarity(m)
    src_scaled = o3d.geometry.PointCloud(src)
    src_scaled.scale(scaled.scale, center=np.zeros(3))
    src_scaled.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel_size, max_nn=30))
    rigid = np.eye(4)
    rigid[:3, :3] = scaled.rotation
    rigid[:3, 3] = scaled.translation
    result = reg.registration_icp(src_scaled, dst, refine, rigid, reg.TransformationEstimationPointToPlane(), criteria)
    if colored:
        result = reg.registration_colored_icp(src_scaled, dst, refine, result.transformation,
                                              reg.TransformationEstimationForColoredICP(), criteria)
    r = np.asarray(result.transformation)
    final = np.eye(4)
    final[:3, :3] = r[:3, :3] * scaled.scale * prior
    final[:3, 3] = r[:3, 3]
    return GaussianRegistration(_similarity(final), float(result.fitness), float(result.inlier_rmse),
                                ransac_fitness)
