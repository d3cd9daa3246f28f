"""export (URDF joint, static TF command, launch file) and launch/publish.launch.py."""

from __future__ import annotations

import ast
import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from linelaser_calib.cli import main
from linelaser_calib.core.geometry import (
    transform_from_rotation_translation,
    transform_from_translation_quaternion,
)
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.cylinder import CylinderSection
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.export import static_transform_arguments
from linelaser_calib.io.results import write_result_yaml

REPO_ROOT = Path(__file__).resolve().parent.parent


def hand_eyes() -> list[np.ndarray]:
    """Seeded random hand-eyes, plus the two gimbal-lock cases (pitch +-90 deg)."""
    rng = np.random.default_rng(16)
    rotations = list(Rotation.random(12, random_state=rng).as_matrix())
    rotations += [
        Rotation.from_euler("xyz", [0.3, s * np.pi / 2, -1.1]).as_matrix() for s in (1, -1)
    ]
    return [transform_from_rotation_translation(R, rng.normal(0.0, 0.1, 3)) for R in rotations]


def result_of(T: np.ndarray) -> CalibrationResult:
    return CalibrationResult(
        T_flange_sensor=T,
        target=CylinderSection(Cylinder(np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.02)),
        method="default",
        samples_used=[0, 1],
        samples_rejected=[],
        rms_residual_m=5e-6,
        uncertainty_translation_m=np.full(3, 1e-5),
        uncertainty_rotation_rad=np.full(3, 5e-5),
        parent_frame="flange",
        child_frame="scanner",
    )


def transform_from_arguments(words: list[str]) -> tuple[np.ndarray, str, str]:
    """The transform and frames that static_transform_publisher would publish for ``words``."""
    values = dict(zip(words[::2], words[1::2], strict=True))
    t = [float(values[f"--{k}"]) for k in "xyz"]
    q = [float(values[f"--q{k}"]) for k in "xyzw"]
    T = transform_from_translation_quaternion(t, q)
    return T, values["--frame-id"], values["--child-frame-id"]


@pytest.mark.parametrize("index", range(14))
def test_urdf_rpy_gives_the_matrix_back(
    index: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    T = hand_eyes()[index]
    path = write_result_yaml(result_of(T), tmp_path / "result.yaml")
    assert main(["export", str(path), "--format", "urdf"]) == 0
    text = capsys.readouterr().out
    # Pasted into a robot that has the flange link, every link a joint names exists.
    robot = ET.fromstring(f'<robot name="arm"><link name="flange"/>{text}</robot>')
    links = {link.attrib["name"] for link in robot.iter("link")}
    (joint,) = robot.iter("joint")
    assert {joint.find(end).attrib["link"] for end in ("parent", "child")} <= links  # type: ignore[union-attr]
    assert joint.attrib == {"name": "scanner_joint", "type": "fixed"}
    assert joint.find("parent").attrib["link"] == "flange"  # type: ignore[union-attr]
    assert joint.find("child").attrib["link"] == "scanner"  # type: ignore[union-attr]
    origin = joint.find("origin")
    assert origin is not None
    xyz = [float(v) for v in origin.attrib["xyz"].split()]
    roll, pitch, yaw = (float(v) for v in origin.attrib["rpy"].split())
    # URDF: fixed axes x-y-z, R = Rz(yaw) Ry(pitch) Rx(roll)
    Rx = Rotation.from_rotvec([roll, 0.0, 0.0]).as_matrix()
    Ry = Rotation.from_rotvec([0.0, pitch, 0.0]).as_matrix()
    Rz = Rotation.from_rotvec([0.0, 0.0, yaw]).as_matrix()
    np.testing.assert_allclose(Rz @ Ry @ Rx, T[:3, :3], atol=1e-9)
    np.testing.assert_allclose(xyz, T[:3, 3], atol=1e-12)


def test_static_tf_command_publishes_the_result(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    T = hand_eyes()[0]
    path = write_result_yaml(result_of(T), tmp_path / "result.yaml")
    assert main(["export", str(path), "--format", "static-tf"]) == 0
    words = capsys.readouterr().out.split()
    assert words[:4] == ["ros2", "run", "tf2_ros", "static_transform_publisher"]
    published, parent, child = transform_from_arguments(words[4:])
    np.testing.assert_allclose(published, T, atol=1e-9)
    assert (parent, child) == ("flange", "scanner")


def test_exported_launch_file_runs_the_publisher_with_the_result(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    T = hand_eyes()[1]
    path = write_result_yaml(result_of(T), tmp_path / "result.yaml")
    assert main(["export", str(path), "--format", "launch"]) == 0
    tree = ast.parse(capsys.readouterr().out)
    calls = [
        n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "Node"
    ]
    assert len(calls) == 1
    keywords = {k.arg: ast.literal_eval(k.value) for k in calls[0].keywords}
    assert (keywords["package"], keywords["executable"]) == (
        "tf2_ros",
        "static_transform_publisher",
    )
    published, parent, child = transform_from_arguments(keywords["arguments"])
    np.testing.assert_allclose(published, T, atol=1e-9)
    assert (parent, child) == ("flange", "scanner")


def test_export_of_a_missing_result_is_a_user_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["export", str(tmp_path / "none.yaml"), "--format", "urdf"]) == 1
    err = capsys.readouterr().err
    assert "none.yaml" in err and "Traceback" not in err


def load_publish_launch() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "publish_launch", REPO_ROOT / "launch" / "publish.launch.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_publish_launch_publishes_the_result_frames_and_transform(tmp_path: Path) -> None:
    module = load_publish_launch()
    T = hand_eyes()[2]
    result = result_of(T)
    path = write_result_yaml(result, tmp_path / "result.yaml")
    words = module.node_arguments(str(path))
    assert words[::2] == static_transform_arguments(result)[::2]  # the same flags, in order
    published, parent, child = transform_from_arguments(words)
    np.testing.assert_allclose(published, T, atol=1e-9)
    assert (parent, child) == ("flange", "scanner")
    if importlib.util.find_spec("launch_ros") is None:
        with pytest.raises(RuntimeError, match="--format static-tf"):
            module.generate_launch_description()


def test_an_estimated_along_line_scale_is_named_beside_the_export(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """No transform carries the profiler's scale: the export says so on stderr and leaves its
    own text (stdout, for a file) as it is."""
    plain = result_of(hand_eyes()[0])
    scaled = result_of(hand_eyes()[0])
    scaled.target = CylinderSection(
        Cylinder(np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.02),
        scale=0.0081,
        scale_sigma=2e-4,
        depth_scale=-0.002,
        depth_scale_sigma=5e-4,
    )
    outputs = []
    for name, result in (("plain", plain), ("scaled", scaled)):
        path = tmp_path / f"{name}.yaml"
        write_result_yaml(result, path)
        assert main(["export", str(path), "--format", "urdf"]) == 0
        outputs.append(capsys.readouterr())
    assert outputs[0].out == outputs[1].out
    assert outputs[0].err == ""
    assert "along-line (x) scale was estimated as 1.00810" in outputs[1].err
    assert "+0.81 % +- 0.02 %" in outputs[1].err
    assert "depth (z) scale was estimated as 0.99800" in outputs[1].err
