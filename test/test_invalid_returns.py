"""A profiler's sentinel for no return (Keyence -999.999 mm, or 0) through bags and the CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from linelaser_calib.cli import main
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.types import Profile
from linelaser_calib.io.bags import read_bag, write_bag
from linelaser_calib.io.results import read_result_yaml
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.simulate import simulate

KEYENCE_NO_RETURN_M = -0.999999


def test_keyence_sentinel_rows_are_dropped_like_nan_and_calibrate_to_truth(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = scenario_from_preset("ur_scancontrol", n_poses=12, resolution=300)
    data = simulate(scenario, 4)
    marked = []
    for profile in data.profiles:
        points = profile.points.copy()
        points[~np.all(np.isfinite(points), axis=1)] = [0.0, 0.0, KEYENCE_NO_RETURN_M]
        marked.append(Profile(profile.stamp_ns, points, profile.frame_id))
    bag = write_bag(tmp_path / "keyence", marked, data.poses)

    plain = read_bag(bag)
    cleaned = read_bag(bag, invalid_values_m=[KEYENCE_NO_RETURN_M])
    for raw, ours, original in zip(plain.profiles, cleaned.profiles, data.profiles, strict=True):
        n_valid = int(np.all(np.isfinite(original.points), axis=1).sum())
        assert len(ours.points) == n_valid
        assert len(raw.points) == len(original.points)  # the sentinel rows look like points
        assert np.all(ours.points[:, 2] > 0.0)

    out = tmp_path / "result.yaml"
    argv = ["calibrate", str(bag), "--invalid-value", str(KEYENCE_NO_RETURN_M)]
    assert main([*argv, "--output", str(out)]) == 0
    rot, trans = transform_error(read_result_yaml(out).T_flange_sensor, data.truth.T_flange_sensor)
    assert np.degrees(rot) < 0.05 and trans < 1e-4
    with pytest.raises(SystemExit) as usage:
        main(["calibrate", str(bag), "--invalid-value", "nan"])
    assert usage.value.code == 2
    assert "NaN and +-Inf are always no return" in capsys.readouterr().err
