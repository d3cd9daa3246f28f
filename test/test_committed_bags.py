"""The committed bags are what their recorded command regenerates.

Simulated bags hold ``truth.yaml`` with the simulator command; bags converted from real
recordings hold ``reference.yaml`` with the convert command (run when the source folder is
present, which lies outside the repository).

Regenerated on another machine, computed floats may differ from the committed ones in their
last bits, so floats are compared with tolerances (``_compare``); stamps, counts, topics,
frames and every other non-float value exactly.
"""

from __future__ import annotations

import shlex
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest
import yaml
from _compare import assert_float32_close, assert_floats_close, assert_trees_close

from linelaser_calib.cli import main
from linelaser_calib.core.robot.kinematics import JointStates
from linelaser_calib.io.bags import BagContents, read_bag, read_joint_states

ROOT = Path(__file__).resolve().parent.parent
BAGS = ROOT / "bags"
COMMITTED = sorted(p.parent for p in BAGS.glob("*/metadata.yaml"))
SIMULATED = [bag for bag in COMMITTED if (bag / "truth.yaml").is_file()]
CONVERTED = [bag for bag in COMMITTED if (bag / "reference.yaml").is_file()]


class Recording(NamedTuple):
    """What a simulator command writes: the bag, truth.yaml, (weld seams) initial.yaml and
    (arms with kinematics) the joint states."""

    bag: BagContents
    truth: dict[str, Any]
    initial: dict[str, Any] | None
    joint_states: JointStates | None = None


def load(directory: Path) -> Recording:
    def parsed(name: str) -> dict[str, Any] | None:
        path = directory / name
        return yaml.safe_load(path.read_text()) if path.exists() else None

    truth = parsed("truth.yaml")
    assert truth is not None
    truth["simulation"].pop("command")  # names the output directory
    joints = read_joint_states(directory) if "kinematics" in truth else None
    return Recording(read_bag(directory), truth, parsed("initial.yaml"), joints)


def assert_same_recording(new: Recording, old: Recording) -> None:
    assert_trees_close(new.truth, old.truth)
    assert_trees_close(new.initial, old.initial)
    assert_same_bag(new.bag, old.bag)
    assert (new.joint_states is None) == (old.joint_states is None)
    if new.joint_states is not None and old.joint_states is not None:
        assert new.joint_states.names == old.joint_states.names
        np.testing.assert_array_equal(new.joint_states.stamps_ns, old.joint_states.stamps_ns)
        assert_floats_close(
            new.joint_states.positions, old.joint_states.positions, err_msg="joint states"
        )


def assert_same_bag(a: BagContents, b: BagContents) -> None:
    assert (a.profile_topic, a.pose_topic) == (b.profile_topic, b.pose_topic)
    assert (a.sensor_frame, a.base_frame) == (b.sensor_frame, b.base_frame)
    assert len(a.profiles) == len(b.profiles), f"{len(a.profiles)} profiles, not {len(b.profiles)}"
    assert len(a.poses) == len(b.poses), f"{len(a.poses)} poses, not {len(b.poses)}"
    for k, (pa, pb) in enumerate(zip(a.profiles, b.profiles, strict=True)):
        assert (pa.stamp_ns, pa.frame_id) == (pb.stamp_ns, pb.frame_id)
        assert_float32_close(pa.points, pb.points, err_msg=f"profile {k}")
    for k, (fa, fb) in enumerate(zip(a.poses, b.poses, strict=True)):
        assert (fa.stamp_ns, fa.frame_id) == (fb.stamp_ns, fb.frame_id)
        assert_floats_close(fa.T_base_flange, fb.T_base_flange, err_msg=f"pose {k}")


def test_committed_bags_exist_and_are_small() -> None:
    assert len(SIMULATED) >= 2 and len(CONVERTED) >= 1
    assert sorted(SIMULATED + CONVERTED) == COMMITTED
    total = sum(f.stat().st_size for bag in COMMITTED for f in bag.iterdir())
    assert total < 10_000_000, f"committed bags take {total} bytes"


@pytest.mark.parametrize("bag", CONVERTED, ids=lambda p: p.name)
def test_converted_bag_regenerates_from_its_command(bag: Path, tmp_path: Path) -> None:
    reference = yaml.safe_load((bag / "reference.yaml").read_text(encoding="utf-8"))
    words = shlex.split(reference["conversion"]["command"])
    assert words[:2] == ["linelaser-calib", "convert"]
    assert words[-2:] == ["--output", f"bags/{bag.name}"]
    source = ROOT / words[3]
    if not source.is_dir():
        pytest.skip(f"the source recordings {source} are not on this machine")
    assert (bag / "LICENSE").read_bytes() == (source / "LICENSE").read_bytes()
    out = tmp_path / bag.name
    assert main(["convert", words[2], str(source), "--output", str(out)]) == 0
    assert_same_bag(read_bag(out), read_bag(bag))


@pytest.mark.parametrize("bag", SIMULATED, ids=lambda p: p.name)
def test_bag_regenerates_from_its_command(bag: Path, tmp_path: Path) -> None:
    words = shlex.split(yaml.safe_load((bag / "truth.yaml").read_text())["simulation"]["command"])
    assert words[:3] == ["linelaser-calib", "simulate", f"bags/{bag.name}"]
    out = tmp_path / bag.name
    assert main(["simulate", str(out), *words[3:]]) == 0
    assert_same_recording(load(out), load(bag))


def nudged(tree: Any) -> Any:
    """``tree`` with every float moved by three last-bit steps."""
    if isinstance(tree, dict):
        return {key: nudged(value) for key, value in tree.items()}
    if isinstance(tree, list):
        return [nudged(value) for value in tree]
    if isinstance(tree, float):
        return float(np.nextafter(np.nextafter(np.nextafter(tree, np.inf), np.inf), np.inf))
    return tree


def test_regeneration_check_ignores_last_bits_and_catches_real_changes() -> None:
    """Another machine's last-bit differences pass; a change of 1 um or a count does not."""
    old = load(BAGS / "weld_seam")
    bag = old.bag
    float32_step = [
        replace(p, points=np.nextafter(p.points.astype(np.float32), np.float32(np.inf)))
        for p in bag.profiles
    ]
    last_bits = [
        replace(f, T_base_flange=f.T_base_flange * (1.0 + 4e-16) + 3e-16) for f in bag.poses
    ]
    other = Recording(
        replace(bag, profiles=float32_step, poses=last_bits), nudged(old.truth), nudged(old.initial)
    )
    assert_same_recording(other, old)

    moved = [*bag.poses]
    T = moved[5].T_base_flange.copy()
    T[0, 3] += 1e-6
    moved[5] = replace(moved[5], T_base_flange=T)
    with pytest.raises(AssertionError, match="pose 5"):
        assert_same_recording(old._replace(bag=replace(bag, poses=moved)), old)
    truth = nudged(old.truth)
    truth["hand_eye"]["translation"][2] += 1e-6
    with pytest.raises(AssertionError, match=r"hand_eye.translation\[2\]"):
        assert_same_recording(old._replace(truth=truth), old)
    with pytest.raises(AssertionError, match="19 profiles, not 20"):
        assert_same_recording(old._replace(bag=replace(bag, profiles=bag.profiles[1:])), old)
