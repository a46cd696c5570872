"""Measurement helpers shared by the evaluation reports: progress, timing, error metrics, formatting."""

from __future__ import annotations

import math
import os
import sys
import time
from typing import Any, Callable, Iterable, Sequence, TypeAlias, TypeVar, cast

import numpy as np
import numpy.typing as npt

T = TypeVar("T")

# One measurement of a report: column name -> value (a number, or a string such as "" for a cell
# that does not apply); the reports' rows, their CSV lines and their markdown tables are made of these.
Row: TypeAlias = dict[str, Any]

# The fusion policies every report compares, in the order tables and plots list them.
POLICIES = ("mean", "softmax", "occupancy")


class Progress:
    """A bar redrawn on stderr when it is a terminal, as the CLI's; nothing otherwise, or when
    AVSPLAT_QUIET is set (``avsplat --quiet eval``)."""

    def __init__(self, label: str, total: int) -> None:
        self.label, self.total, self.done = label, max(int(total), 1), 0
        self.start = time.perf_counter()
        self.terminal = sys.stderr.isatty() and not os.environ.get("AVSPLAT_QUIET")

    def advance(self, detail: str = "") -> None:
        self.done = min(self.total, self.done + 1)
        elapsed = time.perf_counter() - self.start
        if self.terminal:
            filled = 30 * self.done // self.total
            bar = "#" * filled + "." * (30 - filled)
            sys.stderr.write(f"\r\033[K{self.label} [{bar}] {self.done}/{self.total} {elapsed:.1f} s {detail[-40:]}")
            sys.stderr.flush()
            if self.done == self.total:
                sys.stderr.write("\r\033[K")
                sys.stderr.flush()


def best_time(fn: Callable[[], T], repeats: int) -> tuple[T, float]:
    """(result of the last call, smallest wall time in seconds over `repeats` calls)."""
    best, result = math.inf, cast(T, None)  # fn is called at least once
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return result, best


def max_abs(a: npt.ArrayLike, b: npt.ArrayLike) -> float:
    """max |a - b| (equal infinities count as no error, any other non-finite value as infinite)."""
    x = np.asarray(a, dtype=np.float64)
    y = np.asarray(b, dtype=np.float64)
    if x.size == 0:
        return 0.0
    with np.errstate(invalid="ignore"):
        d = np.abs(x - y)
    d[x == y] = 0.0
    d[~np.isfinite(d)] = np.inf
    return float(d.max())


def max_err(a: npt.ArrayLike, ref: npt.ArrayLike) -> float:
    """max |a - ref| / max(1, |ref|): the absolute error for values up to 1 (colours, weights),
    the relative error for larger ones (scales of 1e4, coordinates of 1e6)."""
    x = np.asarray(a, dtype=np.float64)
    r = np.asarray(ref, dtype=np.float64)
    if x.size == 0:
        return 0.0
    with np.errstate(invalid="ignore"):
        d = np.abs(x - r) / np.maximum(1.0, np.abs(r))
    d[x == r] = 0.0
    d[~np.isfinite(d)] = np.inf
    return float(d.max())


def finite(*arrays: npt.ArrayLike) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(a)))) for a in arrays)


def fmt(v: float, digits: int = 3) -> str:
    if isinstance(v, float) and not math.isfinite(v):
        return "inf" if v > 0 else "nan"
    return f"{v:.{digits}g}"


def aggregate(rows: Iterable[Row], key_fields: Sequence[str],
              value: str) -> dict[tuple[Any, ...], tuple[float, float]]:
    """{key: (mean, std)} of value over the rows sharing key_fields."""
    groups: dict[tuple[Any, ...], list[Any]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in key_fields), []).append(r[value])
    return {k: (float(np.mean(v)), float(np.std(v))) for k, v in groups.items()}
