"""The layering the package promises: core is pure numpy/scipy/opencv, nodes are the only ROS,
no import circle anywhere (``TYPE_CHECKING`` imports counted), and the ground floor of core
imports nothing above it."""

from __future__ import annotations

import ast
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CORE = sorted((ROOT / "linelaser_calib" / "core").rglob("*.py"))
PACKAGES = ("linelaser_calib", "msg_adapters")
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


@pytest.mark.parametrize("path", CORE, ids=lambda p: str(p.relative_to(ROOT)))
def test_core_imports_no_ros_io_or_plotting(path: Path) -> None:
    bad = {
        r
        for r in imported_roots(path)
        if r in FORBIDDEN_IN_CORE or r.startswith("linelaser_calib.")
    }
    assert not bad, f"{path.name} imports {sorted(bad)}"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def own_modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}


def imported_modules(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's own modules that ``path`` imports, wherever the import sits (in a
    function, under ``TYPE_CHECKING``): ``from pkg import sub`` counts as ``pkg.sub``."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            for alias in node.names:
                sub = f"{module}.{alias.name}"
                found.add(sub if sub in modules else module)
    return {m for m in found if m in modules and m != name}


def import_graph() -> dict[str, set[str]]:
    modules = own_modules()
    return {name: imported_modules(name, path, modules) for name, path in modules.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (or a self-loop)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    names = sorted(graph)
    index = {n: i for i, n in enumerate(names)}
    edges = [(index[a], index[b]) for a in names for b in graph[a]]
    rows, cols = zip(*edges, strict=True) if edges else ((), ())
    matrix = coo_matrix(([1] * len(edges), (rows, cols)), shape=(len(names), len(names)))
    _, labels = connected_components(matrix, directed=True, connection="strong")
    groups: dict[int, list[str]] = {}
    for name, label in zip(names, labels, strict=True):
        groups.setdefault(int(label), []).append(name)
    return [g for g in groups.values() if len(g) > 1]


def test_no_import_circle_in_the_package_counting_type_checking_imports() -> None:
    found = circles(import_graph())
    assert not found, f"import circles: {found}"


def test_the_circle_finder_sees_a_circle_through_type_checking() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert circles(graph) == [["a", "b", "c"]]


#: The ground floor of core: records and helpers every stage uses; they import no other
#: module of the package but each other (and only downwards in this order).
GROUND_FLOOR = ("errors", "geometry", "types")


def test_the_ground_floor_of_core_imports_nothing_above_it() -> None:
    graph = import_graph()
    floor = {f"linelaser_calib.core.{m}" for m in GROUND_FLOOR}
    for module in floor:
        assert graph[module] <= floor, f"{module} imports {sorted(graph[module] - floor)}"


def test_the_solver_and_the_shared_profile_code_know_no_target() -> None:
    graph = import_graph()
    for name, imports in graph.items():
        if name.startswith(("linelaser_calib.core.solver", "linelaser_calib.core.profile")):
            targets = {m for m in imports if m.startswith("linelaser_calib.core.targets")}
            assert not targets, f"{name} imports {sorted(targets)}"


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
            "tf2_msgs",
            "launch",
            "launch_ros",
            "ament_index_python",
        )
    },
}
#: Run, never imported: launch/publish.launch.py starts tf2_ros's static_transform_publisher.
RUN_ONLY = {"tf2_ros"}


def test_every_imported_dependency_is_declared_and_every_declared_one_imported() -> None:
    sources = [*(ROOT / "linelaser_calib").rglob("*.py"), *(ROOT / "msg_adapters").rglob("*.py")]
    sources += (ROOT / "launch").glob("*.py")
    own = {"linelaser_calib", "msg_adapters", "__future__"}
    imported = set().union(*(imported_roots(p) for p in sources))
    third_party = {r for r in imported if r.split(".")[0] not in own | set(sys.stdlib_module_names)}
    assert third_party == set(DEPENDENCIES), "update DEPENDENCIES, package.xml, requirements.txt"
    manifest = ET.parse(ROOT / "package.xml").getroot()
    exec_depends = {e.text for e in manifest.iter("exec_depend")}
    assert exec_depends == {key for key, _ in DEPENDENCIES.values()} | RUN_ONLY
    pinned = {
        line.split("==")[0]
        for line in (ROOT / "requirements.txt").read_text().splitlines()
        if "==" in line and not line.startswith("#")
    }
    missing = {pypi for _, pypi in DEPENDENCIES.values() if pypi is not None} - pinned
    assert not missing, f"not pinned in requirements.txt: {sorted(missing)}"


def test_a_target_imports_no_sibling_target() -> None:
    """What two targets share lives in core (profile/, seam_grid.py, ...) or in the targets'
    own shared modules (base.py, runs.py), not in one of them."""
    prefix = "linelaser_calib.core.targets."
    for name, imports in import_graph().items():
        if not name.startswith(prefix) or name.count(".") < 4:
            continue
        own = name.split(".")[3]
        siblings = {m for m in imports if m.startswith(prefix) and m.split(".")[3] != own}
        siblings -= {prefix + "base", prefix + "runs"}
        assert not siblings, f"{name} imports {sorted(siblings)}"
