"""The TF tree (core), /tf + /tf_static in bags, and --pose-source tf against the pose topic."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from linelaser_calib.cli import main
from linelaser_calib.core.geometry import (
    interpolate_transform,
    invert_transform,
    rotvec_from_matrix,
    transform_from_rotvec_translation,
)
from linelaser_calib.core.tf import (
    StampedTransform,
    TfChainError,
    TransformTree,
    base_frame_warning,
    live_flange_poses,
)
from linelaser_calib.core.types import FlangePose
from linelaser_calib.io.bags import read_bag, write_bag
from linelaser_calib.io.pose_sources import PoseRequest, poses_from_tf
from linelaser_calib.io.results import read_result_yaml
from linelaser_calib.settings import Front, render
from linelaser_calib.sim.bag_writer import simulate_to_bag
from linelaser_calib.sim.tf_chain import ur_tf_tree

MS = 1_000_000


def random_transform(rng: np.random.Generator) -> np.ndarray:
    return transform_from_rotvec_translation(rng.normal(size=3), rng.normal(size=3))


def test_lookup_interpolates_each_dynamic_edge_and_composes_through_the_common_ancestor() -> None:
    rng = np.random.default_rng(1)
    # world -s-> base ; world -s-> a -d-> b -d-> tool0 ; the two dynamic edges at other stamps
    T_world_base, T_world_a = random_transform(rng), random_transform(rng)
    ab = {s: random_transform(rng) for s in (0, 10 * MS, 20 * MS)}
    bt = {s: random_transform(rng) for s in (4 * MS, 14 * MS)}
    tree = TransformTree()
    tree.extend(
        [
            StampedTransform(0, "world", "base", T_world_base),
            StampedTransform(0, "world", "a", T_world_a),
        ],
        static=True,
    )
    tree.extend([StampedTransform(s, "a", "b", T) for s, T in ab.items()], static=False)
    tree.extend([StampedTransform(s, "b", "tool0", T) for s, T in bt.items()], static=False)

    stamp = 7 * MS
    T_ab = interpolate_transform(ab[0], ab[10 * MS], 0.7)
    T_bt = interpolate_transform(bt[4 * MS], bt[14 * MS], 0.3)
    expected = invert_transform(T_world_base) @ T_world_a @ T_ab @ T_bt
    got = tree.lookup("base", "tool0", stamp, tolerance_s=0.02)
    assert not isinstance(got, str)
    np.testing.assert_allclose(got, expected, atol=1e-12)

    poses = tree.flange_poses("base", "tool0", tolerance_s=0.02)
    assert [p.stamp_ns for p in poses] == [0, 4 * MS, 10 * MS, 14 * MS, 20 * MS]
    # 20 ms is 6 ms from the last tool0 transform: beyond a 4.5 ms tolerance, left out
    poses = tree.flange_poses("base", "tool0", tolerance_s=0.0045)
    assert [p.stamp_ns for p in poses] == [0, 4 * MS, 10 * MS, 14 * MS]
    assert all(p.frame_id == "base" for p in poses)
    reason = tree.lookup("base", "tool0", 7 * MS, tolerance_s=0.002)
    assert isinstance(reason, str) and reason.startswith("b -> tool0: ")


def test_a_second_parent_is_refused_and_reported() -> None:
    tree = TransformTree()
    tree.add(StampedTransform(0, "base_link", "tool0", np.eye(4)), static=True)
    tree.add(StampedTransform(5, "world", "tool0", np.eye(4)), static=False)
    assert tree.parent_of("tool0") == "base_link"
    assert any("tool0 has parent base_link" in c for c in tree.conflicts)
    batch = [StampedTransform(s, "a" if s % 2 else "b", "c", np.eye(4)) for s in range(1, 7)]
    tree.extend(batch, static=False)
    assert tree.parent_of("c") == "a"
    assert [p.stamp_ns for p in tree.flange_poses("a", "c", 1.0)] == [1, 3, 5]
    assert any("c has parent a but transforms give it parent b" in c for c in tree.conflicts)


def test_missing_static_transform_names_frames_gap_and_the_tf2_echo_command() -> None:
    poses_tree = TransformTree()
    dynamic, static = ur_tf_tree(
        [FlangePose(0, np.eye(4)), FlangePose(MS, np.eye(4))], "base_link", "tool0"
    )
    poses_tree.extend([t for t in static if t.child != "base_link_inertia"], static=True)
    poses_tree.extend(dynamic, static=False)
    with pytest.raises(TfChainError) as err:
        poses_tree.chain("base_link", "tool0")
    text = render(str(err.value), Front.CLI)
    assert "tool0 -> flange -> wrist_3_link" in text
    assert "no transform gives base_link_inertia a parent" in text
    assert "shoulder_link <- base_link_inertia (dynamic, 2 stamps)" in text
    assert "between base_link_inertia and base_link" in text
    assert "/tf_static" in text and "--pose-source pose" in text
    assert "`ros2 run tf2_ros tf2_echo base_link tool0`" in text


def test_ur_base_warning_only_when_the_frames_disagree() -> None:
    warning = base_frame_warning("base", "base_link")
    assert warning is not None and "180 deg about z" in warning and "TCP" in warning
    assert base_frame_warning("base", "base") is None
    assert base_frame_warning("base_link", "base_link") is None


@pytest.fixture(scope="module")
def tf_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """ur_scancontrol, 14 poses, with the /tf chain and /tf_static beside the pose topic."""
    out = tmp_path_factory.mktemp("tf") / "bag"
    simulate_to_bag(out, "ur_scancontrol", 3, {"n_poses": 14}, tf=True)
    return out


def test_tf_chain_of_the_simulator_reproduces_the_pose_topic(tf_bag: Path) -> None:
    bag = read_bag(tf_bag)
    from_tf = poses_from_tf(bag, PoseRequest("base_link", "tool0"))
    assert [p.stamp_ns for p in from_tf.poses] == [p.stamp_ns for p in bag.poses]
    for a, b in zip(from_tf.poses, bag.poses, strict=True):
        np.testing.assert_allclose(a.T_base_flange, b.T_base_flange, atol=1e-12)


def test_pose_source_tf_gives_the_hand_eye_of_the_pose_topic(
    tf_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    results = {}
    for source in ("pose", "tf"):
        out = tmp_path / f"{source}.yaml"
        argv = ["calibrate", str(tf_bag), "--pose-source", source, "--output", str(out)]
        assert main(argv) == 0
        results[source] = read_result_yaml(out)
    assert "poses of TF base_link -> tool0" in capsys.readouterr().out
    pose, tf = results["pose"], results["tf"]
    assert pose.uncertainty_translation_m is not None
    assert pose.uncertainty_rotation_rad is not None
    delta = invert_transform(pose.T_flange_sensor) @ tf.T_flange_sensor
    assert np.all(np.abs(delta[:3, 3]) < 0.1 * pose.uncertainty_translation_m)
    assert np.all(np.abs(rotvec_from_matrix(delta[:3, :3])) < 0.1 * pose.uncertainty_rotation_rad)
    assert tf.base_frame == "base_link" and tf.parent_frame == "tool0"


def test_pose_source_tf_reports_a_recording_without_tf_static(
    tf_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    contents = read_bag(tf_bag)
    dynamic, _ = ur_tf_tree(contents.poses, "base_link", "tool0")
    bag = write_bag(tmp_path / "no_static", contents.profiles, contents.poses, tf=dynamic)
    out = tmp_path / "result.yaml"
    assert main(["calibrate", str(bag), "--pose-source", "tf", "--output", str(out)]) == 1
    err = capsys.readouterr().err
    assert "cannot build the TF chain from base_link to tool0" in err
    assert "tool0" in err and "wrist_3_link <- forearm_link (dynamic" in err
    assert "ros2 run tf2_ros tf2_echo base_link tool0" in err
    assert "Traceback" not in err and not out.exists()
    argv = ["calibrate", str(tf_bag), "--pose-source", "tf", "--pose-topic", "/flange_pose"]
    assert main(argv) == 1
    assert "drop --pose-topic" in capsys.readouterr().err


def test_poses_in_ur_base_warn_when_the_run_says_base_link(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "ur"
    argv = ["simulate", str(bag), "--scenario", "paper", "--seed", "2", "--poses", "12"]
    assert main([*argv, "--points", "300", "--base-frame", "base"]) == 0
    out = tmp_path / "result.yaml"
    assert main(["calibrate", str(bag), "--output", str(out)]) == 0
    warnings = read_result_yaml(out).warnings
    assert any("180 deg about z" in w for w in warnings)
    quiet = tmp_path / "quiet.yaml"
    assert main(["calibrate", str(bag), "--base-frame", "base", "--output", str(quiet)]) == 0
    assert not any("180 deg about z" in w for w in read_result_yaml(quiet).warnings)
    assert "180 deg about z" in capsys.readouterr().out


def test_live_tf_messages_give_the_flange_poses_once_tf_static_arrived() -> None:
    rng = np.random.default_rng(5)
    stream = [FlangePose(k * 8 * MS, random_transform(rng)) for k in range(6)]
    dynamic, static = ur_tf_tree(stream, "base_link", "tool0")
    tree = TransformTree(max_age_s=1.0)
    poses, problems = live_flange_poses(tree, dynamic[:3], "base_link", "tool0", 0.02)
    assert poses == [] and "cannot build the TF chain from base_link to tool0" in problems[0]
    tree.extend(static, static=True)
    received = []
    for k in range(1, 6):  # one message per stamp, as robot_state_publisher sends
        poses, problems = live_flange_poses(
            tree, dynamic[3 * k : 3 * k + 3], "base_link", "tool0", 0.02
        )
        assert problems == [] and [p.stamp_ns for p in poses] == [stream[k].stamp_ns]
        received += poses
    for got, sent in zip(received, stream[1:], strict=True):
        np.testing.assert_allclose(got.T_base_flange, sent.T_base_flange, atol=1e-12)


def test_why_no_pose_names_the_missing_link_or_the_stale_ones() -> None:
    stream = [FlangePose(k * 2 * MS, np.eye(4)) for k in range(50)]  # 500 Hz for 0.1 s
    dynamic, static = ur_tf_tree(stream, "base_link", "tool0")
    tree = TransformTree(max_age_s=1.0)
    tree.extend(dynamic, static=False)
    tree.extend([t for t in static if t.child != "tool0"], static=True)
    why = tree.why_no_pose("base_link", "tool0", 50 * MS, 0.02)
    assert why is not None and "tool0 does not appear in any transform" in why
    tree.extend(static, static=True)
    assert tree.why_no_pose("base_link", "tool0", 50 * MS, 0.02) is None
    why = tree.why_no_pose("base_link", "tool0", 1598 * MS, 0.02)  # the stream stopped at 98 ms
    assert why is not None
    for link in ("shoulder_link", "forearm_link", "wrist_3_link"):
        assert f"-> {link} is stale: its newest transform on /tf is 1.500 s older" in why
