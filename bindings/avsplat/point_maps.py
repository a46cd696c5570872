"""Gaussians from point maps (C++ module ``point_maps``): one flat Gaussian per valid pixel, sized
by the pixel footprint or by its nearest neighbours."""

from ._avsplat import gaussians_from_point_maps

__all__ = ["gaussians_from_point_maps"]
