"""Leave out what a scene does not need (C++ module ``reduce``): ``prune`` Gaussians no camera
sees, ``reduce_sh`` drops SH bands below a colour bound, ``simplify`` reduces to a budget of
Gaussians (merge or voxel method)."""

from ._avsplat import PruneResult, ReduceShResult, SimplifyResult, prune, reduce_sh, simplify

__all__ = ["PruneResult", "ReduceShResult", "SimplifyResult", "prune", "reduce_sh", "simplify"]
