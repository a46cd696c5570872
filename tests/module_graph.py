"""Holds every #include under lib/ to the module graph written in lib/module_graph.txt.

Fails (exit 1, one line per offence) on: an include of a module that the including module does
not build on (directly or transitively), a cycle in the graph, a module directory the graph does
not name, and a public header (lib/include) that includes a private one (lib/src), which an
installed tree would not have.

    python3 tests/module_graph.py [LIB_DIR]
"""
from __future__ import annotations

import pathlib
import re
import sys

INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]', re.M)
SOURCES = {".h", ".hpp", ".cpp", ".cu", ".cuh"}


def read_graph(path: pathlib.Path) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for number, raw in enumerate(path.read_text().splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if ":" not in line:
            raise SystemExit(f"{path}:{number}: expected 'module: dependencies'")
        name, deps = line.split(":", 1)
        graph[name.strip()] = set(deps.split())
    for name, deps in graph.items():
        for dep in deps - graph.keys():
            raise SystemExit(f"{path}: {name} builds on '{dep}', which the graph does not name")
    return graph


def closure(graph: dict[str, set[str]]) -> tuple[dict[str, set[str]], list[str]]:
    """Every module's transitive dependencies, and the modules that lie on a cycle."""
    reach: dict[str, set[str]] = {}
    cyclic: list[str] = []
    for start in graph:
        seen: set[str] = set()
        stack = list(graph[start])
        while stack:
            m = stack.pop()
            if m not in seen:
                seen.add(m)
                stack.extend(graph[m])
        reach[start] = seen
        if start in seen:
            cyclic.append(start)
    return reach, cyclic


def module_of(path: pathlib.Path, lib: pathlib.Path) -> tuple[str, bool]:
    """(module, public) of a file under lib/include/avsplat/<m>/ or lib/src/<m>/."""
    rel = path.relative_to(lib).parts
    if rel[0] == "include":
        return rel[2], True
    return rel[1], False


def target_of(include: str, modules: set[str], lib: pathlib.Path) -> tuple[str, bool] | None:
    """(module, public) an include names, or None for a system or third-party header."""
    parts = include.split("/")
    if parts[0] == "avsplat" and len(parts) > 2:
        return parts[1], True
    if len(parts) > 1 and parts[0] in modules and (lib / "src" / include).exists():
        return parts[0], False
    return None


def check(lib: pathlib.Path) -> list[str]:
    graph = read_graph(lib / "module_graph.txt")
    reach, cyclic = closure(graph)
    errors = [f"module_graph.txt: '{m}' lies on a cycle" for m in cyclic]
    modules = set(graph)
    for folder in [*(lib / "include" / "avsplat").iterdir(), *(lib / "src").iterdir()]:
        if folder.is_dir() and folder.name not in modules:
            errors.append(f"{folder.relative_to(lib.parent)}: module '{folder.name}' is not in lib/module_graph.txt")
    for path in sorted([*(lib / "include").rglob("*"), *(lib / "src").rglob("*")]):
        if path.suffix not in SOURCES or not path.is_file():
            continue
        source, public = module_of(path, lib)
        if source not in modules:
            continue
        text = path.read_text(errors="replace")
        for match in INCLUDE.finditer(text):
            target = target_of(match.group(1), modules, lib)
            if target is None:
                continue
            name, target_public = target
            line = text.count("\n", 0, match.start()) + 1
            where = f"{path.relative_to(lib.parent)}:{line}"
            if name not in modules:
                errors.append(f"{where}: includes '{match.group(1)}' of unknown module '{name}'")
            elif name != source and name not in reach[source]:
                errors.append(f"{where}: {source} includes '{match.group(1)}' but does not build on {name}")
            if public and not target_public:
                errors.append(f"{where}: public header includes private '{match.group(1)}'")
    return errors


def main() -> int:
    lib = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).parents[1] / "lib")
    errors = check(lib.resolve())
    for e in errors:
        print(e)
    print(f"module graph: {len(errors)} offence(s)")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
