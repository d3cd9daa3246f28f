"""The committed bags are exactly what their recorded simulator command regenerates."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import pytest

from linelaser_calib.cli import main
from linelaser_calib.io.bags import read_bag
from linelaser_calib.io.results import read_truth_yaml

BAGS = Path(__file__).resolve().parent.parent / "bags"
COMMITTED = sorted(p.parent for p in BAGS.glob("*/metadata.yaml"))


def test_committed_bags_exist_and_are_small() -> None:
    assert len(COMMITTED) >= 2
    total = sum(f.stat().st_size for bag in COMMITTED for f in bag.iterdir())
    assert total < 4_000_000, f"committed bags take {total} bytes"


@pytest.mark.parametrize("bag", COMMITTED, ids=lambda p: p.name)
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
    old, new = read_bag(bag), read_bag(out)
    assert (old.profile_topic, old.pose_topic) == (new.profile_topic, new.pose_topic)
    assert len(old.profiles) == len(new.profiles) and len(old.poses) == len(new.poses)
    for a, b in zip(old.profiles, new.profiles, strict=True):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.points, b.points)
    for a, b in zip(old.poses, new.poses, strict=True):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.T_base_flange, b.T_base_flange)
