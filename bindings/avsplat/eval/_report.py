"""The one report writer: every evaluation report is written as <name>.csv, <name>.png and
<name>.md in the same way, so a new report only measures rows and says how to draw and describe
them (see write_report)."""

from __future__ import annotations

import csv
import math
import os
import platform
import shlex
from types import ModuleType
from typing import TYPE_CHECKING, Callable, Sequence

from ._common import Row

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def md_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _cpuinfo() -> dict[str, str]:
    info: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if not line.strip():
                    break  # the first processor's block is enough
                info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    return info


def _thp() -> str:
    try:
        with open("/sys/kernel/mm/transparent_hugepage/enabled") as f:
            line = f.read().strip()  # "always [madvise] never"
    except OSError:
        return "?"
    return line[line.find("[") + 1:line.find("]")] if "[" in line else line


def machine() -> str:
    """The machine, and how busy it was: timings depend on both, so benchmarks and reports print
    this beside their figures (CPU model and x86 family/model: Zen 3 is family 25 model 1, Zen 4
    family 25 model 17, Zen 5 family 26; AVX2/AVX-512; cores, threads, transparent huge pages)."""
    threads = os.environ.get("OMP_NUM_THREADS", str(os.cpu_count()))
    wait = os.environ.get("OMP_WAIT_POLICY")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    cpu = _cpuinfo()
    flags = set(cpu.get("flags", "").split())
    model = (f"{cpu.get('model name', platform.processor() or platform.machine())} (family "
             f"{cpu.get('cpu family', '?')} model {cpu.get('model', '?')}, AVX2 {'yes' if 'avx2' in flags else 'no'}, "
             f"AVX-512 {'yes' if 'avx512f' in flags else 'no'})")
    return (f"{model}, {platform.system()}, {os.cpu_count()} CPU cores, OpenMP threads {threads}"
            + (f", OMP_WAIT_POLICY={wait}" if wait else "") + f", transparent huge pages {_thp()}"
            + f", load average {load:.1f} when measured")


def command(name: str, out_dir: str, quick: bool) -> str:
    """The command lines that regenerate report `name` into `out_dir`: the avsplat tool, and the
    Python module it runs (with whatever interpreter and PYTHONPATH make avsplat importable)."""
    args = f"{name} -o {shlex.quote(out_dir)}" + (" --quick" if quick else "")
    # OpenMP settings change the timings, so the command says which were used.
    env = "".join(f"{k}={os.environ[k]} " for k in ("OMP_NUM_THREADS", "OMP_WAIT_POLICY") if k in os.environ)
    return f"{env}avsplat eval {args}\n# runs: {env}python3 -m avsplat.evaluation {args}"


def pyplot() -> ModuleType:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _csv_value(v: object) -> object:
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "nan")
    return v


def write_csv(path: str, rows: Sequence[Row], columns: Sequence[str]) -> None:
    """One line per row, the given columns in order; a missing value is an empty cell, floats are
    written exactly (repr) and non-finite ones as inf, -inf, nan."""
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: _csv_value(r.get(k, "")) for k in columns})


def write_report(out_dir: str, name: str, rows: Sequence[Row], columns: Sequence[str], *,
                 plot: Callable[[ModuleType], Figure], title: str, body: str, quick: bool,
                 dpi: int = 110) -> list[str]:
    """Writes report `name` into out_dir (created if missing) and returns the three paths:

    <name>.csv  `rows` (dicts) restricted to `columns`, in that order
    <name>.png  the figure plot(plt) returns (matplotlib.pyplot, Agg backend), laid out tightly
    <name>.md   "# title", `body` (markdown), then the command that regenerates the report
    """
    os.makedirs(out_dir, exist_ok=True)
    stem = os.path.join(out_dir, name)
    write_csv(stem + ".csv", rows, columns)
    plt = pyplot()
    fig = plot(plt)
    try:
        fig.tight_layout()
        fig.savefig(stem + ".png", dpi=dpi)
    finally:
        plt.close(fig)
    text = (f"# {title}\n\n{body.strip()}\n\nRegenerate with:\n\n```\n"
            f"{command(name, os.path.relpath(out_dir), quick)}\n```\n")
    with open(stem + ".md", "w") as f:
        f.write(text)
    return [stem + ".csv", stem + ".png", stem + ".md"]
