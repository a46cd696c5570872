# Sphinx configuration of the avsplat documentation; built by scripts/docs.sh (warnings as errors)
# from a copy of docs/ plus the pages scripts/docs_generate.py makes from the code.
import os
import re

_root = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
if not os.path.isfile(os.path.join(_root, "CMakeLists.txt")):  # run from docs/ itself
    _root = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
with open(os.path.join(_root, "CMakeLists.txt")) as f:
    release = re.search(r"project\(avsplat\s+VERSION\s+([0-9.]+)", f.read()).group(1)
version = release

project = "avsplat"
author = "the avsplat authors"
copyright = "the avsplat authors, MIT License"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "numpydoc",
    "breathe",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["Doxyfile.in", "_build"]
myst_heading_anchors = 3

# Python reference: numpydoc renders the docstrings; pybind11 puts the signature on their first
# line, which autodoc reads.
autodoc_docstring_signature = True
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_validation_checks = set()

# C++ reference: doxygen XML of lib/include/avsplat (scripts/docs.sh runs doxygen).
breathe_projects = {"avsplat": os.environ.get("AVSPLAT_DOXYGEN_XML", "doxygen/xml")}
breathe_default_project = "avsplat"
breathe_domain_by_extension = {"h": "cpp"}

# The evaluation reports are written by `avsplat eval` with a title and then third-level
# sections; they are shown as written.
suppress_warnings = ["myst.header"]

html_theme = "alabaster"
html_title = f"avsplat {release}"
html_theme_options = {"description": "The geometry side of feed-forward 3D Gaussian Splatting",
                      "fixed_sidebar": True}
