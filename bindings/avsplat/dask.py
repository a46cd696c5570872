"""Distributed fusion on Dask: fuse_voxels / fuse_gaussians on dask arrays chunked along samples.

Fusion is local: a voxel's result depends only on its own samples (put in a canonical order
before any arithmetic), and the in-memory operator returns the voxels in lexicographic order of
their keys k = round(p / voxel_size) (in double, half away from zero). So the samples are routed
to blocks that are ranges of that order, each block is fused by the C++ operator in a worker, and
the blocks' results, concatenated in block order, are the in-memory result bit for bit
(diagnostics included; sample_voxel is global, in input order).

How blocks are chosen. Blocks are ranges of the voxel keys (kx, ky, kz) in lexicographic order
(the operator's output order). Before the graph is built one pass over the positions draws
a uniform random sample of KEY_SAMPLES_PER_BLOCK routing keys per block (seeded per chunk, so
the choice is reproducible) and cuts at its quantiles. Each block then holds the same share of
the samples up to the sampling error, about 1/sqrt(KEY_SAMPLES_PER_BLOCK) relative: blocks stay
within 1.25x of the mean (tested on a dense object in a sparse background) unless a single
voxel holds more samples than a block, which cannot be cut. The number of
blocks is `blocks`, or enough blocks of at most `block_bytes` of input each.

The shuffle is Dask's: each input chunk is split into per-block pieces by one task, each block
task concatenates its pieces in chunk order and fuses them; the scheduler moves the pieces and
recomputes lost ones when a worker dies. Computation runs on the active distributed.Client if
there is one (a LocalCluster, or `distributed.Client("tcp://scheduler:8786")` for a real
cluster), else on Dask's default scheduler.
"""
from __future__ import annotations

import math
import operator
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, Callable, Mapping, NoReturn, Required, Sequence, TypeAlias, TypedDict, cast

import dask
import dask.array as da
import numpy as np
import numpy.typing as npt

from . import _avsplat

if TYPE_CHECKING:
    import argparse

    from .core import GaussianCloud

# What the functions take as an array of samples: a dask array, or a numpy array.
ArrayInput: TypeAlias = "da.Array | npt.NDArray[Any]"
# One input chunk's share of a block: the samples' global indices (int64), then each column's rows.
_Piece: TypeAlias = "tuple[npt.NDArray[Any], ...]"


class _Layout(TypedDict, total=False):
    """The columns a block fuses: their trailing shapes (positions first), whether one is the
    confidence, and the names of the extra channels (Gaussians only)."""

    shapes: Required[list[tuple[int, ...]]]
    confidence: Required[bool]
    extras: list[str]


KEY_SAMPLES_PER_BLOCK = 1000
DEFAULT_BLOCK_BYTES = 256 << 20
# The per-voxel diagnostics of a fusion result and their dtypes.
_DIAGNOSTICS: tuple[tuple[str, type[np.number[Any]]], ...] = (
    ("occupancy", np.int32), ("temperature", np.float32), ("variance", np.float32),
    ("reliability", np.float32), ("kept", np.int32), ("entropy", np.float32))


def voxel_keys(positions: npt.ArrayLike, voxel_size: float) -> npt.NDArray[np.float64]:
    """(N, 3) float64 keys round(p / voxel_size), half away from zero, computed in double exactly
    as the C++ operator does (numpy's round would round half to even). NaN for non-finite p."""
    q = np.asarray(positions, dtype=np.float64) / voxel_size
    t = np.trunc(q)
    frac = q - t
    return t + (frac >= 0.5) - (frac <= -0.5)


def _key_fits(k: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """Per component: finite and within int32, [-2^31, 2^31 - 1] (NaN compares False)."""
    return (k >= -2.0**31) & (k <= 2.0**31 - 1)


def routing_keys(positions: npt.ArrayLike, voxel_size: float) -> tuple[npt.NDArray[np.bytes_], npt.NDArray[np.bool_]]:
    """(N,) routing keys ordered as the voxel keys (kx, ky, kz) are, and the (N,) mask of rows
    with a finite position whose key fits int32. A key is 12 bytes (numpy 'S12'): each component
    plus 2^31 as a big-endian uint32, so that byte order is key order and numpy sorts, compares
    and searches them natively."""
    k = voxel_keys(positions, voxel_size)
    ok = np.all(_key_fits(k), axis=1)
    u = (np.where(ok[:, None], k, 0).astype(np.int64) + (1 << 31)).astype(">u4")
    return np.ascontiguousarray(u).view("S12").ravel(), ok


def _sample_keys(positions: npt.NDArray[np.float32], voxel_size: float, fraction: float,
                 seed: int) -> npt.NDArray[np.bytes_]:
    rng = np.random.default_rng(seed)
    pick = rng.random(len(positions)) < fraction
    keys, ok = routing_keys(positions[pick], voxel_size)
    return keys[ok]


def choose_bounds(positions: da.Array, voxel_size: float, blocks: int) -> npt.NDArray[np.bytes_]:
    """Lower bounds (routing keys) of `blocks` key ranges holding about equal sample counts, from
    a sample of KEY_SAMPLES_PER_BLOCK keys per block; the first range starts at the empty key."""
    n = positions.shape[0]
    fraction = min(1.0, KEY_SAMPLES_PER_BLOCK * blocks / max(n, 1))
    parts = [dask.delayed(_sample_keys)(c, voxel_size, fraction, i)
             for i, c in enumerate(positions.to_delayed().ravel())]
    keys = np.sort(np.concatenate(list(dask.compute(*parts)) + [np.zeros(0, "S12")]))
    bounds = [b""]
    for j in range(1, blocks):
        if len(keys) == 0:
            break
        b = keys[j * len(keys) // blocks]
        if b > bounds[-1] and b > keys[0]:
            bounds.append(b)
    return np.asarray(bounds, dtype="S12")


def _partition(offset: int, bounds: npt.NDArray[np.bytes_], voxel_size: float, raise_invalid: bool,
               *cols: npt.NDArray[np.float32]) -> tuple[list[_Piece], int]:
    """Splits one input chunk into per-block pieces (global indices and columns), in input order
    within each block, plus the count of rows dropped for a non-finite position."""
    positions = cols[0]
    keys, ok = routing_keys(positions, voxel_size)
    if raise_invalid and not ok.all():
        i = int(np.flatnonzero(~ok)[0])
        axis = int(np.flatnonzero(~_key_fits(voxel_keys(positions[i:i + 1], voxel_size))[0])[0])
        raise ValueError(f"positions[{offset + i}, {axis}] = {positions[i, axis]} is not finite or its key does "
                         f"not fit int32 (on_invalid='drop' drops non-finite positions)")
    block = np.searchsorted(bounds, keys, side="right") - 1
    block[~ok] = -1
    order = np.argsort(block, kind="stable")
    starts = np.searchsorted(block[order], np.arange(len(bounds) + 1))
    index = np.arange(offset, offset + len(positions), dtype=np.int64)
    pieces: list[_Piece] = []
    for b in range(len(bounds)):
        rows = order[starts[b]:starts[b + 1]]
        pieces.append((index[rows],) + tuple(c[rows] for c in cols))
    return pieces, int((~ok).sum())


def _concat(parts: Sequence[_Piece], column: int, width: tuple[int, ...]) -> npt.NDArray[Any]:
    arrays = [p[column] for p in parts]
    if not arrays:
        return np.zeros((0,) + width, np.float32)
    return np.concatenate(arrays)


def _globalise(error: ValueError, index: npt.NDArray[np.int64]) -> ValueError:
    """The operator's ValueError with its first "[<block index>" replaced by the global index."""
    import re

    def repl(m: re.Match[str]) -> str:
        i = int(m.group(1))
        return f"[{index[i]}" if i < len(index) else m.group(0)

    return ValueError(re.sub(r"\[(\d+)", repl, str(error), count=1))


def _fuse_block(kind: str, voxel_size: float, policy: str, knobs: Mapping[str, Any], layout: _Layout,
                *parts: _Piece) -> dict[str, Any]:
    """Fuses one block's pieces (one per input chunk, in chunk order) with the C++ operator."""
    index = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
    try:
        return _fuse_block_indexed(kind, voxel_size, policy, knobs, layout, index, parts)
    except ValueError as e:
        raise _globalise(e, index) from None


def _fuse_block_indexed(kind: str, voxel_size: float, policy: str, knobs: Mapping[str, Any], layout: _Layout,
                        index: npt.NDArray[np.int64], parts: Sequence[_Piece]) -> dict[str, Any]:
    cols = [_concat(parts, c + 1, shape) for c, shape in enumerate(layout["shapes"])]
    if kind == "features":
        conf = cols[2] if layout["confidence"] else None
        features = _avsplat.fuse_voxels(cols[0], cols[1], voxel_size, conf, policy=policy, **knobs)
        out: dict[str, Any] = {"positions": np.array(features.positions), "features": np.array(features.features)}
        r: _avsplat.FeatureFusionResult | _avsplat.GaussianFusionResult = features
    else:
        n = len(index)
        cloud = _avsplat.GaussianCloud(cols[0], cols[1], cols[2], cols[3], cols[4].reshape(n, -1, 3),
                                       cols[5] if layout["confidence"] else None)
        for e, name in enumerate(layout["extras"]):
            cloud.set_extra(name, cols[5 + layout["confidence"] + e])
        gaussians = _avsplat.fuse_gaussians(cloud, voxel_size, policy=policy, **knobs)
        r = gaussians
        c = gaussians.cloud
        out = {"means": np.array(c.means), "scales": np.array(c.scales), "rotations": np.array(c.rotations),
               "opacities": np.array(c.opacities), "sh": np.array(c.sh)}
        if layout["confidence"]:
            out["confidence"] = np.array(c.confidence)
        for name in layout["extras"]:
            out["extra:" + name] = np.array(c.extras[name])
    out["voxel_coords"] = np.array(r.voxel_coords)
    for name, _ in _DIAGNOSTICS:
        out[name] = np.array(getattr(r, name))
    out["dropped"] = r.dropped
    out["samples"] = len(index)
    # sample_voxel back per input chunk: (global index, voxel within the block) of each piece.
    local = np.array(r.sample_voxel)
    pieces: list[tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]] = []
    at = 0
    for p in parts:
        m = len(p[0])
        pieces.append((p[0], local[at:at + m]))
        at += m
    out["sample_voxel"] = pieces
    return out


def _block_offsets(*voxels: int) -> npt.NDArray[np.int64]:
    return np.concatenate([[0], np.cumsum(voxels)]).astype(np.int64)


def _assemble_sample_voxel(offset: int, length: int, offsets: npt.NDArray[np.int64],
                           *pieces: tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]) -> npt.NDArray[np.int32]:
    sv = np.full(length, -1, np.int32)
    for b, (index, local) in enumerate(pieces):
        sv[index - offset] = np.where(local < 0, -1, local + offsets[b]).astype(np.int32)
    return sv


def _total(*counts: int) -> int:
    return int(sum(counts))


class DaskFusionResult(SimpleNamespace):
    """The lazy result of avsplat.dask.fuse_voxels / fuse_gaussians: dask arrays named as the
    fields of FeatureFusionResult / GaussianFusionResult (M rows of unknown size until computed;
    sample_voxel chunked as the input), `dropped` and `block_samples` (samples per block) as 0-d
    and 1-d dask arrays. compute() evaluates them all in one pass and returns a SimpleNamespace
    of numpy arrays."""

    def compute(self, **kwargs: Any) -> SimpleNamespace:
        names = list(vars(self))
        values = dask.compute(*[getattr(self, n) for n in names], **kwargs)
        return SimpleNamespace(**dict(zip(names, values)))

    def __repr__(self) -> str:
        return f"DaskFusionResult({', '.join(sorted(vars(self)))})"


def _as_columns(arrays: Sequence[ArrayInput], chunks: tuple[int, ...]) -> list[da.Array]:
    out: list[da.Array] = []
    for a in arrays:
        if not isinstance(a, da.Array):
            a = np.asarray(a)
            a = cast(da.Array, da.from_array(a, chunks=(chunks,) + a.shape[1:]))
        if a.dtype != np.float32:
            a = cast(da.Array, a.astype(np.float32))
        out.append(a.rechunk((chunks,) + tuple(-1 for _ in a.shape[1:])))
    return out


def _run(kind: str, cols: Sequence[da.Array], voxel_size: float, policy: str, knobs: Mapping[str, Any], layout: _Layout,
         blocks: int | None, block_bytes: int | None,
         output_shapes: Sequence[tuple[str, tuple[int, ...]]]) -> dict[str, Any]:
    positions = cols[0]
    chunks = positions.chunks[0]
    n = positions.shape[0]
    if blocks is None:
        row_bytes = 8 + sum(4 * int(np.prod(c.shape[1:], dtype=np.int64)) for c in cols)
        blocks = max(1, math.ceil(n * row_bytes / (block_bytes or DEFAULT_BLOCK_BYTES)))
    bounds = choose_bounds(positions, voxel_size, int(blocks))
    nb = len(bounds)
    raise_invalid = knobs.get("on_invalid", "raise") == "raise"
    delayed_cols = [c.to_delayed().ravel() for c in cols]
    offsets = np.concatenate([[0], np.cumsum(chunks)]).astype(np.int64)
    partitions = [dask.delayed(_partition, nout=2)(int(offsets[i]), bounds, voxel_size, raise_invalid,
                                                   *[d[i] for d in delayed_cols])
                  for i in range(len(chunks))]
    getitem = dask.delayed(operator.getitem, pure=True)
    results = []
    for b in range(nb):
        parts = [getitem(p[0], b) for p in partitions]
        results.append(dask.delayed(_fuse_block, pure=True)(kind, voxel_size, policy, knobs, layout, *parts))
    voxels = [getitem(r, "voxel_coords") for r in results]
    counts = [dask.delayed(len, pure=True)(v) for v in voxels]
    block_offsets = dask.delayed(_block_offsets, pure=True)(*counts)

    def concat(name: str, tail: tuple[int, ...], dtype: npt.DTypeLike) -> da.Array:
        arrays = [da.from_delayed(getitem(r, name), shape=(np.nan,) + tail, dtype=dtype) for r in results]
        return da.concatenate(arrays) if arrays else da.zeros((0,) + tail, dtype=dtype)

    out = {name: concat(name, tail, np.float32) for name, tail in output_shapes}
    out["voxel_coords"] = concat("voxel_coords", (3,), np.int32)
    for name, dtype in _DIAGNOSTICS:
        out[name] = concat(name, (), dtype)
    sv_pieces = [getitem(r, "sample_voxel") for r in results]
    sample_voxel = [
        da.from_delayed(dask.delayed(_assemble_sample_voxel, pure=True)(
            int(offsets[i]), int(chunks[i]), block_offsets, *[getitem(s, i) for s in sv_pieces]),
            shape=(chunks[i],), dtype=np.int32)
        for i in range(len(chunks))]
    out["sample_voxel"] = da.concatenate(sample_voxel) if sample_voxel else da.zeros((0,), np.int32)
    dropped = dask.delayed(_total, pure=True)(*[p[1] for p in partitions], *[getitem(r, "dropped") for r in results])
    out["dropped"] = da.from_delayed(dropped, shape=(), dtype=np.int64)
    block_samples = dask.delayed(np.array, pure=True)([getitem(r, "samples") for r in results])
    out["block_samples"] = da.from_delayed(block_samples, shape=(nb,), dtype=np.int64)
    return out


def fuse_voxels(positions: ArrayInput, features: ArrayInput, voxel_size: float, confidence: ArrayInput | None = None,
                policy: str = "occupancy", blocks: int | None = None, block_bytes: int | None = None,
                **knobs: Any) -> DaskFusionResult:
    """Fuse raw feature vectors on Dask: ``avsplat.fuse_voxels`` over the active scheduler.

    Parameters
    ----------
    positions : dask.array.Array or numpy.ndarray, shape (N, 3)
        Sample positions, chunked along samples; converted to float32.
    features : array, shape (N, C)
        Feature vectors; rechunked to the chunks of `positions`.
    voxel_size : float
        Edge of a voxel, > 0.
    confidence : array, shape (N,), optional
        Per-sample confidence.
    policy : {"occupancy", "softmax", "mean"}
        As ``avsplat.fuse_voxels``.
    blocks : int, optional
        Number of spatial blocks; by default enough blocks of at most `block_bytes` of input.
        Blocks are balanced from a sample of the voxel keys (see the module documentation).
    block_bytes : int, optional
        Input bytes per block when `blocks` is not given (default 256 MiB).
    **knobs
        The other keywords of ``avsplat.fuse_voxels``.

    Returns
    -------
    DaskFusionResult
        Dask arrays ``positions`` (M, 3), ``features`` (M, C), ``voxel_coords`` (M, 3), the
        per-voxel diagnostics (M,), ``sample_voxel`` (N,), ``dropped`` and ``block_samples``;
        computed, every array equals the in-memory ``avsplat.fuse_voxels`` result bit for bit.

    Raises
    ------
    TypeError, ValueError
        Here, for bad shapes or knobs; ValueError naming the global index of an invalid sample
        when computed (unless ``on_invalid="drop"``).

    Notes
    -----
    The key sample that chooses the blocks is computed eagerly (one pass over `positions`).
    """
    positions = cast(da.Array, da.asarray(positions))
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"positions: expected shape (N, 3), got {positions.shape}")
    n = positions.shape[0]
    if not isinstance(features, da.Array):
        features = np.asarray(features)
    if features.ndim != 2 or features.shape[0] != n:
        raise ValueError(f"features: expected shape ({n}, C), got {features.shape}")
    c = features.shape[1]
    # Validates the knobs up front (the workers would raise them only at compute time).
    _avsplat.fuse_voxels(np.zeros((0, 3), np.float32), np.zeros((0, c), np.float32), voxel_size,
                         None if confidence is None else np.zeros(0, np.float32), policy=policy, **knobs)
    arrays = [positions, features]
    if confidence is not None:
        if confidence.shape != (n,):
            raise ValueError(f"confidence: expected shape ({n},), got {confidence.shape}")
        arrays.append(confidence)
    cols = _as_columns(arrays, positions.rechunk({1: -1}).chunks[0])
    layout: _Layout = {"shapes": [(3,), (c,)] + ([()] if confidence is not None else []),
              "confidence": confidence is not None}
    out = _run("features", cols, voxel_size, policy, knobs, layout, blocks, block_bytes,
               [("positions", (3,)), ("features", (c,))])
    return DaskFusionResult(**out)


def fuse_gaussians(means: ArrayInput, scales: ArrayInput, rotations: ArrayInput, opacities: ArrayInput,
                   sh: ArrayInput, voxel_size: float, confidence: ArrayInput | None = None,
                   extras: Mapping[str, ArrayInput] | None = None, policy: str = "occupancy",
                   blocks: int | None = None, block_bytes: int | None = None, **knobs: Any) -> DaskFusionResult:
    """Fuse Gaussians on Dask: ``avsplat.fuse_gaussians`` over the active scheduler.

    Parameters
    ----------
    means, scales : array, shape (N, 3)
        Dask or numpy arrays chunked along samples (rechunked to the chunks of `means`).
    rotations : array, shape (N, 4)
        Quaternions (w, x, y, z).
    opacities : array, shape (N,)
        Opacities in [0, 1].
    sh : array, shape (N, K, 3)
        SH coefficients, K = 1, 4, 9 or 16.
    voxel_size : float
        Edge of a voxel, > 0.
    confidence : array, shape (N,), optional
        Per-Gaussian confidence.
    extras : dict of str to array of shape (N,), optional
        Extra channels, fused like the other fields.
    policy : {"occupancy", "softmax", "mean"}
        As ``avsplat.fuse_gaussians``.
    blocks, block_bytes : int, optional
        As ``avsplat.dask.fuse_voxels``.
    **knobs
        The other keywords of ``avsplat.fuse_gaussians`` (``shape`` included).

    Returns
    -------
    DaskFusionResult
        ``means``, ``scales``, ``rotations``, ``opacities``, ``sh`` (M, K, 3), ``confidence``
        (when given), ``extras`` (dict of (M,) arrays), ``positions`` (= means),
        ``voxel_coords``, the diagnostics, ``sample_voxel``, ``dropped`` and ``block_samples``,
        each equal to the in-memory ``avsplat.fuse_gaussians`` result bit for bit once computed.

    Raises
    ------
    ValueError
        For bad shapes or knobs, here; for invalid samples, when computed.
    """
    means = cast(da.Array, da.asarray(means))
    n = means.shape[0]
    sh = cast(da.Array, da.asarray(sh))
    if sh.ndim != 3 or sh.shape[0] != n or sh.shape[2] != 3:
        raise ValueError(f"sh: expected shape ({n}, K, 3), got {sh.shape}")
    k = sh.shape[1]
    extras = dict(extras or {})
    probe = _avsplat.GaussianCloud(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0),
                                   np.zeros((0, k, 3)), None if confidence is None else np.zeros(0))
    _avsplat.fuse_gaussians(probe, voxel_size, policy=policy, **knobs)
    arrays = [means, scales, rotations, opacities, da.asarray(sh).reshape(n, 3 * k)]
    shapes: list[tuple[int, ...]] = [(3,), (3,), (4,), (), (3 * k,)]
    for name, a, width in (("scales", scales, 3), ("rotations", rotations, 4)):
        if tuple(np.shape(a)) != (n, width):
            raise ValueError(f"{name}: expected shape ({n}, {width}), got {np.shape(a)}")
    if tuple(np.shape(opacities)) != (n,):
        raise ValueError(f"opacities: expected shape ({n},), got {np.shape(opacities)}")
    if confidence is not None:
        arrays.append(confidence)
        shapes.append(())
    for name, a in extras.items():
        if tuple(np.shape(a)) != (n,):
            raise ValueError(f"extras['{name}']: expected shape ({n},), got {np.shape(a)}")
        arrays.append(a)
        shapes.append(())
    cols = _as_columns(arrays, means.rechunk({1: -1}).chunks[0])
    layout: _Layout = {"shapes": shapes, "confidence": confidence is not None, "extras": list(extras)}
    output_shapes: list[tuple[str, tuple[int, ...]]] = [("means", (3,)), ("scales", (3,)), ("rotations", (4,)),
                                                        ("opacities", ()), ("sh", (k, 3))]
    if confidence is not None:
        output_shapes.append(("confidence", ()))
    output_shapes += [("extra:" + name, ()) for name in extras]
    out = _run("gaussians", cols, voxel_size, policy, knobs, layout, blocks, block_bytes, output_shapes)
    out["extras"] = {name: out.pop("extra:" + name) for name in extras}
    out["positions"] = out["means"]
    return DaskFusionResult(**out)


def _load_feature_npz(path: str) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32],
                                          npt.NDArray[np.float32] | None]:
    """(positions, features, confidence or None) of a raw-feature prediction .npz, the valid
    samples in order: the library's one reader of the layout (avsplat.read_prediction_npz)."""
    samples = _avsplat.read_prediction_npz(path)
    if samples.kind != "features":
        raise OSError(f"{path}: --scheduler fuses raw-feature .npz files (points, features[, confidence, valid]); "
                      f"this one holds {samples.description}")
    assert samples.positions is not None and samples.features is not None
    return samples.positions, samples.features, samples.confidence


def _parse_knob(text: str) -> tuple[str, float | str]:
    name, _, value = text.partition("=")
    try:
        return name, float(value)
    except ValueError:
        return name, value


class _OutputFailed(Exception):
    """The output could not be written (exit code 4)."""


def _write_atomically(path: str, write: Callable[[str], object]) -> None:
    """Calls write(tmp) on a hidden file beside `path` and renames it to `path`; the hidden file
    is removed when write raises, and an OSError becomes _OutputFailed."""
    import os

    head, tail = os.path.split(os.path.abspath(path))
    tmp = os.path.join(head, f".partial-{os.getpid()}-{tail}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as e:
        raise _OutputFailed(f"{path}: {e}") from e
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


# Exit codes of `avsplat --help`: 2 usage, 3 input, 4 output, 5 memory, 130 Ctrl-C.
def _fail(code: int, message: str) -> NoReturn:
    import sys

    print(f"avsplat: error: {message}", file=sys.stderr)
    raise SystemExit(code)


def _fuse_feature_files(paths: Sequence[str], args: argparse.Namespace, knobs: dict[str, Any]) -> SimpleNamespace:
    loaded = [_load_feature_npz(p) for p in paths]
    if len({x[1].shape[1] for x in loaded}) != 1 or len({x[2] is None for x in loaded}) != 1:
        _fail(3, "the inputs differ in feature channels or in having a confidence")
    cols: list[da.Array] = []
    for k in range(3 if loaded[0][2] is not None else 2):
        # k < 2, or every input has a confidence (checked above).
        parts = [cast("npt.NDArray[np.float32]", x[k]) for x in loaded]
        cols.append(da.concatenate([da.from_array(a, chunks=(args.chunk,) + a.shape[1:]) for a in parts]))
    got = fuse_voxels(cols[0], cols[1], args.voxel, cols[2] if len(cols) == 3 else None, policy=args.policy,
                      blocks=args.blocks, **knobs).compute()

    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:
            np.savez(f, positions=got.positions, features=got.features, voxel_coords=got.voxel_coords,
                     **{name: getattr(got, name) for name, _ in _DIAGNOSTICS})

    _write_atomically(args.output, write)
    return got


def _fuse_gaussian_files(paths: Sequence[str], args: argparse.Namespace, knobs: dict[str, Any]) -> SimpleNamespace:
    clouds = [_avsplat.read_gaussians(p) for p in paths]
    first = clouds[0]
    for p, c in zip(paths, clouds):
        if (c.sh_degree, c.confidence is None, list(c.extras)) != (first.sh_degree, first.confidence is None,
                                                                   list(first.extras)):
            _fail(3, f"{p}: SH degree, confidence or extra channels differ from {paths[0]}")

    def column(get: Callable[[GaussianCloud], npt.NDArray[np.float32]]) -> da.Array:
        return da.concatenate([da.from_array(get(c), chunks=(args.chunk,) + get(c).shape[1:]) for c in clouds])

    def extra(name: str) -> Callable[[GaussianCloud], npt.NDArray[np.float32]]:
        return lambda c: c.extras[name]

    r = fuse_gaussians(column(lambda c: c.means), column(lambda c: c.scales), column(lambda c: c.rotations),
                       column(lambda c: c.opacities), column(lambda c: c.sh), args.voxel,
                       confidence=None if first.confidence is None else column(lambda c: c.confidence),
                       extras={name: column(extra(name)) for name in first.extras},
                       policy=args.policy, blocks=args.blocks, **knobs)
    got = r.compute()
    cloud = _avsplat.GaussianCloud(got.means, got.scales, got.rotations, got.opacities, got.sh,
                                   confidence=None if first.confidence is None else got.confidence)
    for name, values in got.extras.items():
        cloud.set_extra(name, values)
    _write_atomically(args.output, lambda tmp: _avsplat.write_gaussians(tmp, cloud))
    return got


def main(argv: Sequence[str] | None = None) -> None:
    """`python3 -m avsplat.dask --scheduler ADDRESS INPUT... -o OUT --voxel V`: fusion on a Dask
    cluster (what `avsplat fuse --scheduler` runs). Raw-feature prediction .npz inputs (points,
    features[, confidence, valid]) fuse with fuse_voxels into an .npz with the keys of `avsplat
    fuse`'s raw-feature output; Gaussian files (3DGS PLY or any format read_gaussians reads) fuse
    with fuse_gaussians into a Gaussian file (by OUT's name). The inputs are read by this process
    and sent to the workers; the output is written to a hidden file, then renamed into place."""
    import argparse

    import distributed

    ap = argparse.ArgumentParser(prog="python3 -m avsplat.dask", description=main.__doc__)
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--voxel", type=float, required=True)
    ap.add_argument("--scheduler", required=True, help="scheduler address, e.g. tcp://10.0.0.5:8786")
    ap.add_argument("--policy", default="occupancy")
    ap.add_argument("--knob", action="append", default=[], help="NAME=VALUE, a fuse_voxels keyword knob")
    ap.add_argument("--blocks", type=int, default=None)
    ap.add_argument("--chunk", type=int, default=1 << 20, help="samples per dask chunk")
    args = ap.parse_args(argv)
    knobs = dict(_parse_knob(k) for k in args.knob)
    npz = [p.lower().endswith(".npz") for p in args.inputs]
    if any(npz) and not all(npz):
        _fail(2, "inputs mix raw-feature .npz files and Gaussian files; fuse one kind at a time")
    if all(npz) != args.output.lower().endswith(".npz"):
        _fail(2, f"{args.output}: raw features fuse to an .npz, Gaussians to a Gaussian file")
    if all(npz):
        knobs.pop("shape", None)  # a knob of Gaussian fusion only
    try:
        client = distributed.Client(args.scheduler, timeout="30s")
    except (ValueError, TypeError) as e:
        _fail(2, f"--scheduler {args.scheduler!r}: not a scheduler address ({e})")
    except (OSError, TimeoutError) as e:
        _fail(2, f"--scheduler {args.scheduler!r}: cannot reach the scheduler ({e})")
    try:
        with client:
            fuse = _fuse_feature_files if all(npz) else _fuse_gaussian_files
            got = fuse(args.inputs, args, knobs)
    except _OutputFailed as e:
        _fail(4, str(e))
    except MemoryError:
        _fail(5, "out of memory")
    except KeyboardInterrupt:
        _fail(130, "interrupted by SIGINT; unfinished outputs were not written")
    except (OSError, ValueError) as e:
        _fail(3, str(e))
    print(f"fused {len(got.sample_voxel)} samples into {len(got.voxel_coords)} voxels in {len(got.block_samples)} "
          f"blocks on {args.scheduler}; wrote {args.output}")


if __name__ == "__main__":
    main()
