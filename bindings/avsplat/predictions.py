"""A feed-forward model's predictions in a numpy .npz (C++ module ``predictions``): the one reader
of the layout, shared by ``avsplat fuse``, the Python API and :mod:`avsplat.dask`."""

from ._avsplat import PredictionSamples, read_prediction_npz

__all__ = ["PredictionSamples", "read_prediction_npz"]
