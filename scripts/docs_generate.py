#!/usr/bin/env python3
"""Writes the documentation pages that are made from the code, so that they cannot drift from it.

    docs_generate.py ROOT SRC      (run by scripts/docs.sh with PYTHONPATH=ROOT/build/python)

  SRC/reference/cli.md       every `avsplat <command> --help`, run on ROOT/build/apps/avsplat
  SRC/reference/python.rst   autodoc entries for every public name of `avsplat` and its modules
  SRC/reference/cpp.md       one breathe `doxygenfile` per public header (lib/include/avsplat/**)
  SRC/reference/fusion_knobs.md  the fusion knobs, from avsplat.fusion.fusion_knobs() (the one table)
  SRC/reports/               the evaluation reports and their figures (apps/benchmarks/reports)
"""
import importlib
import inspect
import os
import pathlib
import pkgutil
import re
import shutil
import subprocess
import sys


def help_text(exe, args):
    # Run as `avsplat` (found on PATH), so that the usage lines name the tool, not a build path.
    env = dict(os.environ, PATH=os.path.dirname(exe) + os.pathsep + os.environ.get("PATH", ""))
    r = subprocess.run(["avsplat", *args, "--help"], capture_output=True, text=True, timeout=120, env=env)
    if r.returncode != 0:
        sys.exit(f"docs_generate: `avsplat {' '.join(args)} --help` exited {r.returncode}:\n{r.stderr}")
    return r.stdout.rstrip()


def subcommands(text):
    """The names CLI11 lists under SUBCOMMANDS: in a help text."""
    names, inside = [], False
    for line in text.splitlines():
        if re.match(r"^subcommands:", line, flags=re.I):
            inside = True
            continue
        if inside:
            m = re.match(r"^  (\S+)", line)
            if m:
                names.append(m.group(1))
            elif line.strip() and not line.startswith(" "):
                inside = False
    return names


def write_cli(root, src):
    exe = str(root / "build" / "apps" / "avsplat")
    top = help_text(exe, [])
    out = ["# Command-line reference", "",
           "Generated when the documentation is built, from the tool's own `--help` "
           "(`build/apps/avsplat <command> --help`).", "",
           "## avsplat", "", "```text", top, "```", ""]
    for name in subcommands(top):
        text = help_text(exe, [name])
        out += [f"## avsplat {name}", "", "```text", text, "```", ""]
        for sub in subcommands(text):
            out += [f"### avsplat {name} {sub}", "", "```text", help_text(exe, [name, sub]), "```", ""]
    (src / "reference" / "cli.md").write_text("\n".join(out))


def public_names(module, top_level):
    """Public names of a module: its __all__, else the names it defines (for avsplat itself:
    every public attribute, since the package re-exports the compiled module)."""
    if hasattr(module, "__all__"):
        names = list(module.__all__)
    else:
        names = []
        for name, obj in vars(module).items():
            if name.startswith("_") or inspect.ismodule(obj):
                continue
            owner = getattr(obj, "__module__", None)
            if top_level or owner == module.__name__:
                names.append(name)
    return sorted(n for n in names if not inspect.ismodule(getattr(module, n)))


def entry(module_name, name, obj):
    if inspect.isclass(obj):
        if issubclass(obj, BaseException):
            return f".. autoexception:: {module_name}.{name}\n"
        return f".. autoclass:: {module_name}.{name}\n   :members:\n   :undoc-members:\n"
    if callable(obj):
        return f".. autofunction:: {module_name}.{name}\n"
    return f".. autodata:: {module_name}.{name}\n   :annotation:\n"


def write_python(src):
    """Every public name of every module, each object documented once: under the first module
    (in name order) that lists it, the top level pointing there for the names it re-exports."""
    import avsplat
    modules = []
    for info in pkgutil.walk_packages(avsplat.__path__, "avsplat."):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts[1:]):
            continue
        modules.append(importlib.import_module(info.name))
    modules.sort(key=lambda m: m.__name__)
    where = {}  # id(object) -> the documented full name
    sections = []
    for module in modules:
        entries = []
        for name in public_names(module, False):
            obj = getattr(module, name)
            if id(obj) in where:
                continue
            where[id(obj)] = f"{module.__name__}.{name}"
            entries.append(entry(module.__name__, name, obj))
        if not entries:
            continue
        title = f"``{module.__name__}``"
        section = [title, "-" * len(title), "", f".. module:: {module.__name__}", ""]
        doc = inspect.getdoc(module)
        if doc:
            section += [doc.split("\n\n")[0], ""]
        sections += section + entries
    top = []
    for name in public_names(avsplat, True):
        obj = getattr(avsplat, name)
        if id(obj) in where:
            top.append(f"- ``avsplat.{name}``: :py:obj:`{where[id(obj)]}`")
        else:
            where[id(obj)] = f"avsplat.{name}"
            top.append(entry("avsplat", name, obj))
    lines = ["Python API reference", "====================", "",
             "Generated from the docstrings when the documentation is built: every public name of",
             "the ``avsplat`` package and of its modules, each documented once, in the first module",
             "that holds it. Arrays are numpy; the shapes and dtypes are given in each entry.", "",
             "``avsplat``", "-----------", "", ".. module:: avsplat", "",
             inspect.getdoc(avsplat).split("\n\n")[0], "",
             "The top level's names (``avsplat.__all__``) and where each is documented:", ""]
    lines += top + [""] + sections
    (src / "reference" / "python.rst").write_text("\n".join(lines) + "\n")


def write_cpp(root, src):
    """reference/cpp.md, and one page per public header under reference/cpp/ (a header per page:
    breathe gives each the namespace's anchor, which must be unique within a page)."""
    include = root / "lib" / "include"
    headers = sorted(p.relative_to(include).as_posix() for p in include.glob("avsplat/**/*.h"))
    (src / "reference" / "cpp").mkdir(parents=True, exist_ok=True)
    out = ["# C++ API reference", "",
           "Generated from the public headers (`lib/include/avsplat/`) by doxygen and breathe when "
           "the documentation is built, one page per header. Include them as "
           "`#include <avsplat/...>`; link `avsplat::avsplat` (and `avsplat::open3d` for the "
           "Open3D adapter).", ""]
    module = None
    for h in headers:
        mod = h.split("/")[1]
        if mod != module:
            out += ([] if module is None else ["```", ""]) + [f"## {mod}", "", "```{toctree}", ":maxdepth: 1", ""]
            module = mod
        page = h[len("avsplat/"):-2].replace("/", "_")
        out.append(f"cpp/{page}")
        (src / "reference" / "cpp" / f"{page}.md").write_text(
            f"# `{h}`\n\n```{{doxygenfile}} {h}\n```\n")
    out += ["```", ""]
    (src / "reference" / "cpp.md").write_text("\n".join(out))


def write_fusion_knobs(src):
    import avsplat.fusion
    cell = lambda text: str(text).replace("|", "\\|")  # noqa: E731
    out = ["# Fusion knobs", "",
           "Generated from `avsplat.fusion.fusion_knobs()`, the one table from which the keywords of "
           "`fuse_voxels`, `fuse_gaussians` and `FusionStream`, the flags of `avsplat fuse` and their "
           "help texts are made. Defaults are the AVSplat paper's where it gives them.", "",
           "| keyword | flag | default | values | meaning |", "|---|---|---|---|---|"]
    for k in avsplat.fusion.fusion_knobs():
        only = " (fuse_gaussians only)" if k["gaussian_only"] else ""
        out.append(f"| `{k['name']}` | `{k['flag']}` | `{k['default']}` | {cell(k['range'])} | {cell(k['doc'])}{only} |")
    (src / "reference" / "fusion_knobs.md").write_text("\n".join(out) + "\n")


def copy_reports(root, src):
    reports = root / "apps" / "benchmarks" / "reports"
    dest = src / "reports"
    dest.mkdir(parents=True, exist_ok=True)
    for p in sorted(reports.iterdir()):
        if p.suffix in (".png", ".csv"):
            shutil.copy(p, dest / p.name)
        elif p.suffix == ".md":
            # The report's figure goes under its title (the .md written by `avsplat eval` names
            # the tables; the figure is its sibling .png).
            title, _, rest = p.read_text().partition("\n")
            figure = p.with_suffix(".png")
            shown = f"\n![{figure.stem}]({figure.name})\n" if figure.exists() else ""
            (dest / p.name).write_text(title + "\n" + shown + rest)


def main():
    root, src = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    (src / "reference").mkdir(parents=True, exist_ok=True)
    write_cli(root, src)
    write_python(src)
    write_cpp(root, src)
    write_fusion_knobs(src)
    copy_reports(root, src)


if __name__ == "__main__":
    main()
