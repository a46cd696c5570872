"""The former name of :mod:`avsplat.eval` (the evaluation reports); kept so that existing
scripts, ``import avsplat.evaluation.reduction`` and ``python3 -m avsplat.evaluation`` keep
working."""

import importlib
import sys

from avsplat.eval import *  # noqa: F401,F403
from avsplat.eval import REPORTS, main  # noqa: F401

for _name in ("_common", "_report", "reduction", "regimes", "scaling", "stability", "tradeoff", "views"):
    _module = importlib.import_module("avsplat.eval." + _name)
    globals()[_name] = _module
    sys.modules[__name__ + "." + _name] = _module
del _name, _module
