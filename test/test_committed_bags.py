"""The committed bags are exactly what their recorded command regenerates.

Simulated bags hold ``truth.yaml`` with the simulator command; bags converted from real
recordings hold ``reference.yaml`` with the convert command (run when the source folder is
present, which lies outside the repository).
"""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import pytest
import yaml

from linelaser_calib.cli import main
from linelaser_calib.io.bags import read_bag
from linelaser_calib.io.results import read_truth_yaml

ROOT = Path(__file__).resolve().parent.parent
BAGS = ROOT / "bags"
COMMITTED = sorted(p.parent for p in BAGS.glob("*/metadata.yaml"))
SIMULATED = [bag for bag in COMMITTED if (bag / "truth.yaml").is_file()]
CONVERTED = [bag for bag in COMMITTED if (bag / "reference.yaml").is_file()]


def test_committed_bags_exist_and_are_small() -> None:
    assert len(SIMULATED) >= 2 and len(CONVERTED) >= 1
    assert sorted(SIMULATED + CONVERTED) == COMMITTED
    total = sum(f.stat().st_size for bag in COMMITTED for f in bag.iterdir())
    assert total < 4_000_000, f"committed bags take {total} bytes"


def _same_recording(old_bag: Path, new_bag: Path) -> None:
    old, new = read_bag(old_bag), read_bag(new_bag)
    assert (old.profile_topic, old.pose_topic) == (new.profile_topic, new.pose_topic)
    assert len(old.profiles) == len(new.profiles) and len(old.poses) == len(new.poses)
    for a, b in zip(old.profiles, new.profiles, strict=True):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.points, b.points)
    for a, b in zip(old.poses, new.poses, strict=True):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.T_base_flange, b.T_base_flange)


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
    _same_recording(bag, out)


@pytest.mark.parametrize("bag", SIMULATED, ids=lambda p: p.name)
def test_bag_regenerates_from_its_command(bag: Path, tmp_path: Path) -> None:
    truth = read_truth_yaml(bag / "truth.yaml")
    words = shlex.split(truth.raw["simulation"]["command"])
    assert words[:3] == ["linelaser-calib", "simulate", f"bags/{bag.name}"]
    out = tmp_path / bag.name
    assert main(["simulate", str(out), *words[3:]]) == 0
    again = read_truth_yaml(out / "truth.yaml")
    for raw in (again.raw, truth.raw):
        raw["simulation"].pop("command")
    assert again.raw == truth.raw
    np.testing.assert_array_equal(again.T_flange_sensor, truth.T_flange_sensor)
    if (bag / "initial.yaml").exists():
        assert (out / "initial.yaml").read_text() == (bag / "initial.yaml").read_text()
    _same_recording(bag, out)
