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


# Docstrings not yet in numpydoc form (plain text laid out with spaces, as `help()` shows it) are
# shown as they are written, preformatted, instead of being read as reStructuredText; numpydoc
# renders the others. This runs before numpydoc's own handler.
_NUMPYDOC_SECTION = re.compile(r"^\s*(Parameters|Returns|Yields|Raises|Attributes|Methods|Notes|Examples|See Also|Warns)\s*$")


def _preformat_plain_docstrings(app, what, name, obj, options, lines):
    if not any(l.strip() for l in lines):
        return
    numpydoc_form = any(_NUMPYDOC_SECTION.match(a) and set(b.strip()) == {"-"}
                        for a, b in zip(lines, lines[1:]))
    if numpydoc_form:
        return
    body = [("    " + l) if l.strip() else "" for l in lines]
    lines[:] = ["::", ""] + body + [""]


# breathe renders the enclosing namespace once per header, which the C++ domain reports as a
# duplicate declaration; namespaces are meant to be declared by many headers, so only those
# reports are dropped (any other duplicate still fails the build).
def _namespaces():
    import xml.etree.ElementTree as ET
    index = os.path.join(breathe_projects["avsplat"], "index.xml")
    if not os.path.exists(index):
        return set()
    return {c.findtext("name") for c in ET.parse(index).getroot() if c.get("kind") == "namespace"}


class _NamespaceDuplicates:
    def __init__(self, names):
        self.pattern = re.compile(r"Declaration is '\.\. cpp:type:: (" +
                                  "|".join(re.escape(n) for n in sorted(names, key=len, reverse=True)) +
                                  r")'\.$") if names else None

    def filter(self, record):
        if self.pattern is None:
            return True
        return not self.pattern.search(record.getMessage())


def setup(app):
    import logging
    app.connect("autodoc-process-docstring", _preformat_plain_docstrings, priority=100)
    logging.getLogger("sphinx.sphinx.domains.cpp").addFilter(_NamespaceDuplicates(_namespaces()))
