"""The layering the package promises: core is pure numpy/scipy/opencv, nodes are the only ROS."""

from __future__ import annotations

import ast
import subprocess
import sys
import xml.etree.ElementTree as ET
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


#: The rosdep key (package.xml) and the PyPI project (requirements.txt; None: a ROS package
#: or the ROS wheels) of every third-party module the package imports.
DEPENDENCIES = {
    "numpy": ("python3-numpy", "numpy"),
    "scipy": ("python3-scipy", "scipy"),
    "cv2": ("python3-opencv", "opencv-python-headless"),
    "yaml": ("python3-yaml", "PyYAML"),
    "matplotlib": ("python3-matplotlib", "matplotlib"),
    "rosbags": ("python3-rosbags-pip", "rosbags"),
    "mcap": ("mcap-ros2-support", "mcap"),  # rosdep has no key for mcap alone
    **{
        ros: (ros, None)
        for ros in (
            "rclpy",
            "rcl_interfaces",
            "std_msgs",
            "std_srvs",
            "geometry_msgs",
            "sensor_msgs",
            "visualization_msgs",
            "diagnostic_msgs",
            "tf2_ros",
            "tf2_msgs",
            "launch",
            "launch_ros",
            "ament_index_python",
        )
    },
}


def test_every_imported_dependency_is_declared_and_every_declared_one_imported() -> None:
    sources = [*(ROOT / "linelaser_calib").rglob("*.py"), *(ROOT / "msg_adapters").rglob("*.py")]
    sources += (ROOT / "launch").glob("*.py")
    own = {"linelaser_calib", "msg_adapters", "__future__"}
    imported = set().union(*(imported_roots(p) for p in sources))
    third_party = {r for r in imported if r.split(".")[0] not in own | set(sys.stdlib_module_names)}
    assert third_party == set(DEPENDENCIES), "update DEPENDENCIES, package.xml, requirements.txt"
    manifest = ET.parse(ROOT / "package.xml").getroot()
    exec_depends = {e.text for e in manifest.iter("exec_depend")}
    assert exec_depends == {key for key, _ in DEPENDENCIES.values()}
    pinned = {
        line.split("==")[0]
        for line in (ROOT / "requirements.txt").read_text().splitlines()
        if "==" in line and not line.startswith("#")
    }
    missing = {pypi for _, pypi in DEPENDENCIES.values() if pypi is not None} - pinned
    assert not missing, f"not pinned in requirements.txt: {sorted(missing)}"
