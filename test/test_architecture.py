"""The layering the package promises: core is pure numpy/scipy/opencv, nodes are the only ROS."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CORE = sorted((ROOT / "linelaser_calib" / "core").glob("*.py"))
FORBIDDEN_IN_CORE = {"rclpy", "rosbags", "mcap", "mcap_ros2", "yaml", "matplotlib", "msg_adapters"}


def imported_roots(path: Path) -> set[str]:
    roots = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            roots |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
            if node.module.startswith("linelaser_calib.") and not node.module.startswith(
                "linelaser_calib.core"
            ):
                roots.add(node.module)
    return roots


@pytest.mark.parametrize("path", CORE, ids=lambda p: p.name)
def test_core_imports_no_ros_io_or_plotting(path: Path) -> None:
    bad = {
        r
        for r in imported_roots(path)
        if r in FORBIDDEN_IN_CORE or r.startswith("linelaser_calib.")
    }
    assert not bad, f"{path.name} imports {sorted(bad)}"


def test_core_pipeline_loads_without_ros_or_bag_libraries() -> None:
    code = (
        "import sys, linelaser_calib.core.pipeline, linelaser_calib.sim;"
        "bad = sorted(m for m in ('rclpy', 'rosbags', 'mcap', 'yaml') if m in sys.modules);"
        "print(bad); sys.exit(1 if bad else 0)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
