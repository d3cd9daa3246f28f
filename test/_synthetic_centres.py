"""Access to the synthetic-centre generator of ``bench/_common.py`` for the tests.

The generator lives with the benches (one copy); this helper loads it by path, because
``bench/`` is not a package.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

_PATH = Path(__file__).resolve().parents[1] / "bench" / "_common.py"
_NAME = "linelaser_calib_bench_common"

if _NAME not in sys.modules:
    _spec = importlib.util.spec_from_file_location(_NAME, _PATH)
    assert _spec is not None and _spec.loader is not None, f"cannot load {_PATH}"
    sys.modules[_NAME] = importlib.util.module_from_spec(_spec)
    _spec.loader.exec_module(sys.modules[_NAME])

_common = sys.modules[_NAME]
CentreData = _common.CentreData
MM = _common.MM
axis_errors = _common.axis_errors
paper_setup = _common.paper_setup
random_setup = _common.random_setup
synthetic_centres = _common.synthetic_centres
