"""Every user mistake with ``linelaser-calib calibrate`` gives a clear message, no traceback.

Each test builds a small bad recording with the simulator, runs
``linelaser_calib.cli.main([...])`` and checks the exit code and that the message says what
was wrong and what to do. Two tests run the installed executable in a subprocess to prove
that nothing reaches stderr but the one message. Data that is merely dirty (invalid points,
non-unit quaternions, unsorted or duplicate stamps) is handled and still calibrates.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from linelaser_calib.cli import main
from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import invert_transform, transform_error
from linelaser_calib.core.pipeline import PipelineConfig
from linelaser_calib.core.types import FlangePose, Profile
from linelaser_calib.io import read_result_yaml, write_bag
from linelaser_calib.sim import Scenario, scenario_from_preset, simulate
from linelaser_calib.sim.profiler import measure, trace
from linelaser_calib.sim.scene import Scene
from linelaser_calib.sim.simulate import SimulatedData
from msg_adapters import pointcloud2_from_points, pose_stamped_from_flange_pose, rosbags_types

EXECUTABLE = Path(sys.executable).parent / "linelaser-calib"
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
TYPES = rosbags_types(TYPESTORE)
CLOUD = "sensor_msgs/msg/PointCloud2"
POSE = "geometry_msgs/msg/PoseStamped"
NS_PER_S = 1_000_000_000


@pytest.fixture(scope="module")
def scenario() -> Scenario:
    """The paper's scene, small: 12 poses, 300 rays, flange poses at 50 Hz."""
    return scenario_from_preset("paper", n_poses=12, resolution=300, robot_rate_hz=50.0)


@pytest.fixture(scope="module")
def data(scenario: Scenario) -> SimulatedData:
    return simulate(scenario, 7)


@pytest.fixture(scope="module")
def good_bag(tmp_path_factory: pytest.TempPathFactory, data: SimulatedData) -> Path:
    return write_bag(tmp_path_factory.mktemp("good") / "bag", data.profiles, data.poses)


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Exit code, stdout and stderr of ``main(argv)``."""
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def expect_error(argv: list[str], capsys: pytest.CaptureFixture[str], *fragments: str) -> str:
    """Run ``main``; assert exit 1, one error message holding every fragment, no stdout."""
    code, out, err = run_cli(argv, capsys)
    assert code == 1, err
    assert out == ""
    assert err.startswith("linelaser-calib: error: ")
    assert err.count("\n") == 1, err
    for fragment in fragments:
        assert fragment in err, f"{fragment!r} missing from: {err}"
    return err


def write_raw_bag(path: Path, messages: list[tuple[str, str, int, Any]]) -> Path:
    """A bag of (topic, type, log time ns, rosbags message), written in the given order."""
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections: dict[tuple[str, str], Any] = {}
        for topic, msgtype, log_ns, msg in messages:
            key = (topic, msgtype)
            if key not in connections:
                connections[key] = writer.add_connection(topic, msgtype, typestore=TYPESTORE)
            writer.write(connections[key], log_ns, TYPESTORE.serialize_cdr(msg, msgtype))
    return path


def cloud_message(points: np.ndarray, stamp_ns: int) -> Any:
    return pointcloud2_from_points(points, stamp_ns, "laser", types=TYPES)


def pose_message(pose: FlangePose) -> Any:
    return pose_stamped_from_flange_pose(pose, types=TYPES)


def scaled_translation(T: np.ndarray, factor: float) -> np.ndarray:
    scaled = T.copy()
    scaled[:3, 3] *= factor
    return scaled


# --- topics ---------------------------------------------------------------------------------


def test_missing_pose_topic_lists_the_topics(
    tmp_path: Path, data: SimulatedData, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_bag(tmp_path / "bag", data.profiles, [])
    expect_error(
        ["calibrate", str(bag)],
        capsys,
        "no geometry_msgs/msg/PoseStamped messages",
        "/profile (sensor_msgs/msg/PointCloud2, 12 msgs)",
    )


def test_two_profile_topics_are_listed_and_one_can_be_chosen(
    tmp_path: Path, data: SimulatedData, capsys: pytest.CaptureFixture[str]
) -> None:
    messages = [(("/flange_pose", POSE, p.stamp_ns, pose_message(p))) for p in data.poses]
    for profile in data.profiles:
        msg = cloud_message(profile.points, profile.stamp_ns)
        messages += [("/profile", CLOUD, profile.stamp_ns, msg)]
        messages += [("/camera/points", CLOUD, profile.stamp_ns, msg)]
    bag = write_raw_bag(tmp_path / "bag", sorted(messages, key=lambda m: m[2]))
    expect_error(
        ["calibrate", str(bag)],
        capsys,
        "several sensor_msgs/msg/PointCloud2 topics",
        "/camera/points (sensor_msgs/msg/PointCloud2, 12 msgs)",
        "/profile (sensor_msgs/msg/PointCloud2, 12 msgs)",
        "--profile-topic",
    )
    code, out, _ = run_cli(["calibrate", str(bag), "--profile-topic", "/profile"], capsys)
    assert code == 0
    assert "12 used" in out


def test_profile_topic_pointing_at_the_poses_names_both_types(
    good_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    expect_error(
        ["calibrate", str(good_bag), "--profile-topic", "/flange_pose"],
        capsys,
        "has type geometry_msgs/msg/PoseStamped, expected sensor_msgs/msg/PointCloud2",
        "--profile-topic",
    )


def test_unknown_topic_lists_the_existing_ones(
    good_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    expect_error(
        ["calibrate", str(good_bag), "--pose-topic", "/tool_pose"],
        capsys,
        "no topic '/tool_pose'",
        "/flange_pose (geometry_msgs/msg/PoseStamped",
    )


# --- units ----------------------------------------------------------------------------------


def test_profiles_in_millimetres_are_detected(
    tmp_path: Path, data: SimulatedData, capsys: pytest.CaptureFixture[str]
) -> None:
    profiles = [replace(p, points=p.points * 1e3) for p in data.profiles]
    bag = write_bag(tmp_path / "bag", profiles, data.poses)
    expect_error(["calibrate", str(bag)], capsys, "millimetres", "rescale the points by 0.001")


def test_poses_in_millimetres_are_detected(
    tmp_path: Path, data: SimulatedData, capsys: pytest.CaptureFixture[str]
) -> None:
    poses = [replace(p, T_base_flange=scaled_translation(p.T_base_flange, 1e3)) for p in data.poses]
    bag = write_bag(tmp_path / "bag", data.profiles, poses)
    expect_error(["calibrate", str(bag)], capsys, "poses look recorded in millimetres", "by 0.001")


# --- time -----------------------------------------------------------------------------------


def test_profiles_30_s_late_report_the_offset_and_the_fix(
    tmp_path: Path, data: SimulatedData, capsys: pytest.CaptureFixture[str]
) -> None:
    late = [replace(p, stamp_ns=p.stamp_ns + 30 * NS_PER_S) for p in data.profiles]
    bag = write_bag(tmp_path / "bag", late, data.poses)
    err = expect_error(
        ["calibrate", str(bag)],
        capsys,
        "No profile could be paired",
        "median offset",
        "--clock-offset",
        "--sync-tolerance",
    )
    suggested = re.search(r"set the clock offset to about (-?[0-9.]+) s", err)
    assert suggested is not None, err
    assert float(suggested.group(1)) == pytest.approx(-30.0, abs=0.05)
    code, out, _ = run_cli(["calibrate", str(bag), "--clock-offset", "-30"], capsys)
    assert code == 0
    assert "12 used" in out


# --- profiles that do not show the cylinder -------------------------------------------------


def test_all_nan_profiles_say_the_sensor_saw_nothing(
    tmp_path: Path, data: SimulatedData, capsys: pytest.CaptureFixture[str]
) -> None:
    blank = [replace(p, points=np.full_like(p.points, np.nan)) for p in data.profiles]
    bag = write_bag(tmp_path / "bag", blank, data.poses)
    expect_error(["calibrate", str(bag)], capsys, "are empty", "measuring range")


def test_profiles_of_a_plane_give_no_ellipse(
    tmp_path: Path, data: SimulatedData, capsys: pytest.CaptureFixture[str]
) -> None:
    rng = np.random.default_rng(3)
    x = np.linspace(-0.03, 0.03, 300)
    plane = np.column_stack([x, np.zeros_like(x), 0.12 + 0.2 * x])
    profiles = [
        replace(p, points=plane + rng.normal(scale=5e-6, size=plane.shape)) for p in data.profiles
    ]
    bag = write_bag(tmp_path / "bag", profiles, data.poses)
    expect_error(
        ["calibrate", str(bag)],
        capsys,
        "only 0 of 12 recorded profiles gave a usable ellipse",
        "no elliptical arc",
        "None of the profiles shows the cylinder's arc",
    )


def test_diameter_given_as_radius_is_caught(
    good_bag: Path, scenario: Scenario, capsys: pytest.CaptureFixture[str]
) -> None:
    diameter = 2.0 * scenario.cylinder_radius_m
    for method in ("default", "paper"):
        err = expect_error(
            ["calibrate", str(good_bag), "--radius", str(diameter), "--method", method],
            capsys,
            "the given radius 40.00 mm disagrees",
            "not the diameter",
        )
        measured = re.search(r"median semi-minor axis of ([0-9.]+) mm", err)
        assert measured is not None, err
        assert float(measured.group(1)) == pytest.approx(20.0, abs=0.1)


# --- poses that cannot determine the hand-eye -----------------------------------------------


def test_four_poses_are_too_few(
    tmp_path: Path, scenario: Scenario, capsys: pytest.CaptureFixture[str]
) -> None:
    few = simulate(replace(scenario, n_poses=4), 7)
    bag = write_bag(tmp_path / "bag", few.profiles, few.poses)
    expect_error(["calibrate", str(bag)], capsys, "only 4 of 4 recorded profiles", "at least 8")


def translation_only_recording(
    scenario: Scenario, data: SimulatedData, seed: int
) -> tuple[list[Profile], list[FlangePose]]:
    """Profiles from 12 sensor poses that share one orientation (the robot only translates).

    The sensor moves along the cylinder axis and a little across it and in depth from the
    first simulated waypoint; each profile gets three flange poses around its stamp.
    """
    rng = np.random.default_rng(seed)
    first = data.truth.T_base_sensor_waypoints[0]
    axis = scenario.axis_unit
    across = np.cross(axis, first[:3, 2])
    across /= np.linalg.norm(across)
    T_base_sensor = np.repeat(first[None], 12, axis=0)
    T_base_sensor[:, :3, 3] += (
        np.linspace(-0.04, 0.04, 12)[:, None] * axis
        + rng.uniform(-0.004, 0.004, 12)[:, None] * across
        + rng.uniform(-0.01, 0.01, 12)[:, None] * first[:3, 2]
    )
    measured = measure(rng, scenario, trace(Scene.from_scenario(scenario), scenario, T_base_sensor))
    T_sensor_flange = invert_transform(scenario.T_flange_sensor)
    stamps = scenario.epoch_ns + np.arange(12) * NS_PER_S // 2
    profiles = [Profile(int(s), measured.points[k]) for k, s in enumerate(stamps)]
    poses = [
        FlangePose(int(s) + dt, T_base_sensor[k] @ T_sensor_flange)
        for k, s in enumerate(stamps)
        for dt in (-10_000_000, 0, 10_000_000)
    ]
    return profiles, poses


def test_poses_of_one_orientation_name_the_missing_motion(
    tmp_path: Path,
    scenario: Scenario,
    data: SimulatedData,
    capsys: pytest.CaptureFixture[str],
) -> None:
    profiles, poses = translation_only_recording(scenario, data, 11)
    bag = write_bag(tmp_path / "bag", profiles, poses)
    for method in ("default", "paper"):
        expect_error(
            ["calibrate", str(bag), "--method", method],
            capsys,
            "all flange orientations are within",
            "not observable",
            "tilt and rotate the flange",
        )


# --- bags that cannot be read ---------------------------------------------------------------


def test_empty_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = write_bag(tmp_path / "bag", [], [])
    expect_error(["calibrate", str(bag)], capsys, "is empty", "record the profile")


def test_missing_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    expect_error(
        ["calibrate", str(tmp_path / "no_such_bag")], capsys, "does not exist", "check the path"
    )


def test_truncated_bag(tmp_path: Path, good_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(good_bag, bag)
    storage = next(bag.glob("*.mcap"))
    storage.write_bytes(storage.read_bytes()[: storage.stat().st_size // 2])
    err = expect_error(["calibrate", str(bag)], capsys, "truncated or corrupt", "re-record")
    assert ".." not in err
    if shutil.which("mcap") is None:
        assert "mcap CLI (not installed on this machine" in err


def test_a_storage_file_missing_from_the_bag_is_named(
    tmp_path: Path, good_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(good_bag, bag)
    storage = next(bag.glob("*.mcap"))
    storage.unlink()
    err = expect_error(
        ["calibrate", str(bag)], capsys, f"its metadata.yaml names {storage.name}, which is missing"
    )
    assert "truncated" not in err


# --- dirty data is handled ------------------------------------------------------------------


def test_invalid_points_bad_quaternions_and_disordered_stamps_still_calibrate(
    tmp_path: Path, data: SimulatedData, capsys: pytest.CaptureFixture[str]
) -> None:
    """NaN/Inf points, non-unit quaternions, shuffled log order, duplicate stamps."""
    rng = np.random.default_rng(5)
    messages = []
    for profile in data.profiles:
        points = profile.points.copy()
        valid = np.flatnonzero(np.all(np.isfinite(points), axis=1))
        spoiled = rng.choice(valid, 6, replace=False)
        points[spoiled[:2]] = np.nan
        points[spoiled[2:4], 2] = np.inf
        points[spoiled[4:], 0] = -np.inf
        messages.append(
            ("/profile", CLOUD, profile.stamp_ns, cloud_message(points, profile.stamp_ns))
        )
    duplicate = data.profiles[3]
    messages.append(
        ("/profile", CLOUD, duplicate.stamp_ns, cloud_message(duplicate.points, duplicate.stamp_ns))
    )
    for k, pose in enumerate(data.poses):
        msg = pose_message(pose)
        if k % 10 == 0:  # a non-unit quaternion (norm 1.5): skipped with its reason
            q = msg.pose.orientation
            q.x, q.y, q.z, q.w = 1.5 * q.x, 1.5 * q.y, 1.5 * q.z, 1.5 * q.w
        messages.append(("/flange_pose", POSE, pose.stamp_ns, msg))
        if k % 7 == 0:
            messages.append(("/flange_pose", POSE, pose.stamp_ns, msg))
    start = min(m[2] for m in messages)
    shuffled = [messages[i] for i in rng.permutation(len(messages))]
    bag = write_raw_bag(
        tmp_path / "bag",
        [(t, m, start + 1000 * k, msg) for k, (t, m, _, msg) in enumerate(shuffled)],
    )
    output = tmp_path / "result.yaml"
    code, out, err = run_cli(["calibrate", str(bag), "--output", str(output)], capsys)
    assert code == 0, err
    assert "malformed messages were skipped" in out
    quality = yaml.safe_load(output.read_text())["quality"]
    # A summary gives each warning's opening words; its whole text is in the result file.
    assert any("is not unit" in w for w in quality["warnings"])
    assert quality["samples_used"] == 12
    assert [r["reason"] for r in quality["samples_rejected"]] == [
        "duplicate profile stamp; kept first"
    ]
    rotation, translation = transform_error(
        read_result_yaml(output).T_flange_sensor, data.truth.T_flange_sensor
    )
    assert np.degrees(rotation) < 0.05
    assert translation < 2e-4


def test_missing_initial_hand_eye_file_names_the_option(
    tmp_path: Path, good_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    expect_error(
        ["calibrate", str(good_bag), "--initial", str(tmp_path / "cad.yaml")],
        capsys,
        "--initial",
        "cad.yaml does not exist",
    )


# --- outputs --------------------------------------------------------------------------------


def test_output_into_a_missing_directory_fails_before_calibrating(
    tmp_path: Path, good_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "no_such_dir" / "result.yaml"
    expect_error(
        ["calibrate", str(good_bag), "--output", str(target)],
        capsys,
        "does not exist",
        "create the directory first",
    )
    assert not target.parent.exists()


def test_output_below_a_file_is_refused(
    tmp_path: Path, good_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "file.txt"
    blocker.write_text("not a directory\n")
    for option, name in (("--output", "r.yaml"), ("--viz", "v.mcap"), ("--report", "report")):
        expect_error(
            ["calibrate", str(good_bag), option, str(blocker / name)],
            capsys,
            option,
            "is not a directory",
        )


def test_output_that_is_a_directory_is_refused(
    tmp_path: Path, good_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    expect_error(
        ["calibrate", str(good_bag), "--output", str(tmp_path)], capsys, "existing directory"
    )


def test_viz_needs_an_mcap_name(
    tmp_path: Path, good_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    expect_error(
        ["calibrate", str(good_bag), "--viz", str(tmp_path / "viz.yaml")], capsys, "ending in .mcap"
    )


def test_failed_calibration_leaves_an_existing_output_untouched(
    tmp_path: Path, good_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    output = tmp_path / "result.yaml"
    output.write_text("previous: result\n")
    expect_error(
        ["calibrate", str(good_bag), "--radius", "0.04", "--output", str(output)],
        capsys,
        "disagrees",
    )
    assert output.read_text() == "previous: result\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.yaml"]


def test_report_without_matplotlib_says_how_to_get_it(
    tmp_path: Path,
    good_bag: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: None if name == "matplotlib" else real(name, *a),
    )
    expect_error(
        ["calibrate", str(good_bag), "--report", str(tmp_path / "report")],
        capsys,
        "needs matplotlib",
        "pip install matplotlib",
    )
    assert not (tmp_path / "report").exists()


# --- no traceback from the real executable --------------------------------------------------


@pytest.mark.parametrize("case", ["missing_bag", "diameter"])
def test_executable_prints_one_line_and_no_traceback(
    case: str, tmp_path: Path, good_bag: Path
) -> None:
    argv = {
        "missing_bag": ["calibrate", str(tmp_path / "nothing")],
        "diameter": ["calibrate", str(good_bag), "--radius", "0.04"],
    }[case]
    done = subprocess.run(
        [str(EXECUTABLE), *argv], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 1
    assert done.stdout == ""
    assert "Traceback" not in done.stderr
    assert done.stderr.startswith("linelaser-calib: error: ")
    assert done.stderr.count("\n") == 1


FOREIGN_TRUTH = {
    "list": "hand_eye: [1, 2, 3]\n",
    "note": "Calibrated by hand on Tuesday, see the lab book.\n",
    "other_tool": "hand_eye: {translation: [0.1, 0.2, 0.3], rotation_xyzw: [0, 0, 0, 1]}\n",
    "invalid_yaml": "hand_eye: [1, 2\n",
    "damaged_simulator_file": "simulation: {scenario: paper, seed: 1}\nhand_eye: {}\n",
}


@pytest.mark.parametrize("text", FOREIGN_TRUTH.values(), ids=FOREIGN_TRUTH.keys())
def test_a_foreign_truth_yaml_is_skipped_with_one_line(
    text: str, good_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = shutil.copytree(good_bag, tmp_path / "bag")
    (bag / "truth.yaml").write_text(text)
    code, out, err = run_cli(["calibrate", str(bag), "--output", str(tmp_path / "r.yaml")], capsys)
    assert code == 0, err
    assert err.count("\n") == 1 and str(bag / "truth.yaml") in err and "not compared" in err
    assert "Error against truth" not in out
    assert read_result_yaml(tmp_path / "r.yaml").samples_used


def test_the_simulators_truth_yaml_is_compared(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "bag"
    assert main(["simulate", str(bag), "--scenario", "paper", "--poses", "12", "--seed", "7"]) == 0
    capsys.readouterr()
    code, out, err = run_cli(["calibrate", str(bag)], capsys)
    assert code == 0 and err == ""
    assert "Error against truth" in out


@pytest.mark.parametrize("command", ["calibrate", "simulate", "plan"])
def test_a_negative_seed_is_refused_with_its_range(
    command: str, good_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    where = {"calibrate": [str(good_bag)], "simulate": [str(tmp_path / "bag")], "plan": []}
    with pytest.raises(SystemExit) as stop:
        main([command, *where[command], "--seed", "-1"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "--seed: expected a whole number from 0 to 2**32 - 1, got -1" in err
    assert "Traceback" not in err


def test_the_pipeline_refuses_a_seed_numpy_cannot_take() -> None:
    for bad in (-1, 2**32, 1.5):
        with pytest.raises(InputError, match="the seed must be a whole number"):
            PipelineConfig(seed=bad)  # type: ignore[arg-type]


def millimetre_result(tmp_path: Path) -> Path:
    """A result file whose hand-eye translation was written in millimetres."""
    path = tmp_path / "result_mm.yaml"
    path.write_text(
        "hand_eye:\n  parent_frame: tool0\n  child_frame: laser\n"
        "  translation: [80.0, 100.0, 0.0]\n  rotation_xyzw: [0, 0, 0, 1]\n"
        "cylinder: {frame: base_link, point: [0, 0, 0], direction: [0, 0, 1], radius: 0.02}\n"
        "quality: {method: default, samples_used: [0, 1, 2], samples_rejected: [], "
        "rms_residual_m: 5.0e-6, warnings: []}\n",
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize("verb", ["export", "reconstruct", "initial"])
def test_every_command_refuses_a_result_in_millimetres_alike(
    verb: str, good_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One reader, one set of checks: export and reconstruct refuse what --initial refuses."""
    result = millimetre_result(tmp_path)
    out = tmp_path / "cloud.ply"
    argv = {
        "export": ["export", str(result), "--format", "urdf"],
        "reconstruct": [
            "reconstruct",
            str(good_bag),
            "--calibration",
            str(result),
            "--output",
            str(out),
        ],
        "initial": ["calibrate", str(good_bag), "--initial", str(result)],
    }[verb]
    expect_error(argv, capsys, str(result), "128.1 m from the flange: are these millimetres?")
    assert not out.exists()


def test_a_yaml_error_names_the_file_and_the_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("hand_eye:\n  translation: [0.1, 0.2\n  rotation_xyzw: }\n", encoding="utf-8")
    err = expect_error(
        ["export", str(path), "--format", "urdf"], capsys, f"{path} is not valid YAML", "line 3"
    )
    assert "<unicode string>" not in err


def test_a_missing_urdf_is_no_such_file(good_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = expect_error(
        ["calibrate", str(good_bag), "--kinematics", "/nonexistent.urdf"],
        capsys,
        "/nonexistent.urdf: no such file",
    )
    assert "neither a preset" not in err


def test_a_v_seam_swept_in_motion_given_to_the_cylinder_asks_for_the_motion_settings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """With the speed gate on, too few profiles of a seam swept in motion are paired for the
    line target either: no rival explains them, so the cylinder's own refusal stands, naming
    no target and giving the settings of a scan in motion."""
    bag = tmp_path / "seam"
    assert main(["simulate", str(bag), "--scenario", "line", "--poses", "10"]) == 0
    capsys.readouterr()
    err = expect_error(
        ["calibrate", str(bag)],
        capsys,
        "recorded profiles gave a usable ellipse",
        "for a scan in motion give --max-speed 0 --max-angular-speed 0",
    )
    assert "--target" not in err
