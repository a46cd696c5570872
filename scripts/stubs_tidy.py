"""Finishes the stubs stubgen writes for the compiled module, so that mypy accepts them and they
say what pybind11's signatures say:

- numpy.ndarray[numpy.float32] and Eigen's numpy.ndarray[numpy.float64[4, 4]] become
  numpy.typing.NDArray[...]; std::array's List[float[3]] becomes typing.Sequence[float];
- static methods (pybind11's def_static), which stubgen cannot read, are written from their
  docstring signatures with @staticmethod;
- the methods the package adds to GaussianCloud and the module's __version__ are declared.

    PYTHONPATH=build/python python3 scripts/stubs_tidy.py STUB.pyi   (rewrites it in place)
"""
from __future__ import annotations

import importlib
import re
import sys

from mypy.stubdoc import infer_sig_from_docstring

MODULE = "avsplat._avsplat"


def tidy_types(text: str) -> str:
    text = text.replace(MODULE + ".", "")
    text = re.sub(r"List\[(float|int)\[\d+\]\]", r"typing.Sequence[\1]", text)
    text = re.sub(r"numpy\.ndarray\[(numpy\.\w+)(\[[^\]]*\])?\]", r"numpy.typing.NDArray[\1]", text)
    text = re.sub(r"numpy\.ndarray\[bool\]", "numpy.typing.NDArray[numpy.bool_]", text)
    text = re.sub(r"\b(float|int)\[\d+\]", r"\1", text)
    return text


def static_methods(text: str) -> str:
    module = importlib.import_module(MODULE)
    lines = text.split("\n")
    current = None
    for i, line in enumerate(lines):
        match = re.match(r"class (\w+)", line)
        if match:
            current = getattr(module, match.group(1), None)
            continue
        match = re.match(r"(\s+)def (\w+)\(self, \*args, \*\*kwargs\) -> Any: \.\.\.$", line)
        if not match or current is None:
            continue
        indent, name = match.groups()
        raw = vars(current).get(name)
        if not isinstance(raw, staticmethod):
            continue
        sigs = infer_sig_from_docstring(raw.__func__.__doc__, name) or []
        defs = []
        for sig in sigs:
            args = ", ".join(f"{a.name}: {a.type}" + (" = ..." if a.default else "") for a in sig.args)
            defs.append(f"{indent}def {name}({args}) -> {sig.ret_type}: ...")
        if len(defs) == 1:
            lines[i] = f"{indent}@staticmethod\n{defs[0]}"
        elif defs:
            lines[i] = "\n".join(f"{indent}@overload\n{indent}@staticmethod\n{d}" for d in defs)
    return "\n".join(lines)


# The methods avsplat/__init__.py adds to GaussianCloud from the Open3D adapter (Python functions,
# which stubgen sees only as attributes).
OPEN3D_METHODS = {
    "to_open3d": "    def to_open3d(self) -> typing.Any: ...",
    "to_open3d_legacy": "    def to_open3d_legacy(self) -> typing.Any: ...",
    "from_open3d": "    @staticmethod\n"
                   "    def from_open3d(pcd: typing.Any, extra_keys: typing.Optional[typing.Iterable[str]] = ...)"
                   " -> GaussianCloud: ...",
}


def open3d_methods(text: str) -> str:
    for name, stub in OPEN3D_METHODS.items():
        pattern = rf"\n    ({name}: ClassVar\[function\] = \.\.\.|def {name}\(self, \*args, \*\*kwargs\) -> Any: \.\.\.)"
        text = re.sub(pattern, lambda _: "\n" + stub, text)
    return text


def array_like_arguments(text: str) -> str:
    """Array parameters (py::array_t with forcecast, Eigen) accept anything numpy.asarray does."""
    out = []
    for line in text.split("\n"):
        if line.lstrip().startswith("def ") and ") -> " in line:
            params, ret = line.rsplit(") -> ", 1)
            params = re.sub(r"numpy\.typing\.NDArray\[[\w.]+\]", "numpy.typing.ArrayLike", params)
            line = params + ") -> " + ret
        out.append(line)
    return "\n".join(out)


def tidy(text: str) -> str:
    text = array_like_arguments(tidy_types(open3d_methods(static_methods(text))))
    # stubgen leaves out module dunders; the version is API (avsplat.__version__).
    if hasattr(importlib.import_module(MODULE), "__version__") and "__version__" not in text:
        text = text.rstrip("\n") + "\n__version__: str\n"
    if "numpy.typing." in text and "import numpy.typing" not in text:
        text = text.replace("import numpy\n", "import numpy\nimport numpy.typing\n", 1)
    if "typing." in text and "\nimport typing\n" not in text:
        text = text.replace("import numpy\n", "import numpy\nimport typing\n", 1)
    if "@overload" in text and "overload" not in text.split("\n", 1)[0]:
        text = text.replace("from typing import ", "from typing import overload, ", 1)
    return text


def main() -> int:
    path = sys.argv[1]
    with open(path) as f:
        text = f.read()
    with open(path, "w") as f:
        f.write(tidy(text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
