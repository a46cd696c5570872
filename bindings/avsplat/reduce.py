"""Leave out what a scene does not need (C++ module ``reduce``): ``prune`` Gaussians no camera
sees, ``reduce_sh`` drops SH bands below a colour bound, ``simplify`` reduces to a budget of
Gaussians (merge or voxel method), ``build_lod`` makes a level-of-detail set of a scene."""

from ._avsplat import LodBuild, PruneResult, ReduceShResult, SimplifyResult, prune, reduce_sh, simplify, build_lod

__all__ = ["LodBuild", "PruneResult", "ReduceShResult", "SimplifyResult", "prune", "reduce_sh", "simplify", "build_lod"]
