"""The known-point (weld-seam) target end to end through the CLI, against simulator truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from linelaser_calib.cli import main
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.targets.known_point import KnownPoint
from linelaser_calib.io.results import read_result_yaml, read_truth_yaml


@pytest.fixture(scope="module")
def weld_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("weld") / "bag"
    assert main(["simulate", str(bag), "--scenario", "weld_seam_general", "--seed", "4"]) == 0
    return bag


@pytest.mark.parametrize(
    ("method", "rot_deg", "trans_mm"), [("default", 0.2, 0.2), ("paper", 2.0, 2.0)]
)
def test_known_point_corrects_the_bumped_hand_eye(
    weld_bag: Path, tmp_path: Path, method: str, rot_deg: float, trans_mm: float
) -> None:
    truth = read_truth_yaml(weld_bag / "truth.yaml")
    initial = read_result_yaml(weld_bag / "initial.yaml")
    assert isinstance(truth.target, KnownPoint) and isinstance(initial.target, KnownPoint)
    rot0, trans0 = transform_error(initial.T_flange_sensor, truth.T_flange_sensor)
    assert np.degrees(rot0) > 0.9 and trans0 > 0.9e-3  # the old hand-eye is off
    taught = ",".join(str(v) for v in initial.target.point)
    out = tmp_path / "result.yaml"
    code = main(
        [
            "calibrate",
            str(weld_bag),
            "--target",
            "known_point",
            "--point",
            taught,
            "--initial",
            str(weld_bag / "initial.yaml"),
            "--method",
            method,
            "--output",
            str(out),
        ]
    )
    assert code == 0
    result = read_result_yaml(out)
    assert isinstance(result.target, KnownPoint)
    np.testing.assert_allclose(result.target.point, initial.target.point)
    rot, trans = transform_error(result.T_flange_sensor, truth.T_flange_sensor)
    assert np.degrees(rot) < rot_deg and trans * 1e3 < trans_mm
    assert rot < rot0 and trans < trans0


def test_known_point_paper_method_needs_the_taught_point(
    weld_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(
        [
            "calibrate",
            str(weld_bag),
            "--target",
            "known_point",
            "--method",
            "paper",
            "--initial",
            str(weld_bag / "initial.yaml"),
        ]
    )
    assert code == 1
    err = capsys.readouterr().err
    assert "needs --point x,y,z" in err and "taught point" in err


def test_a_known_point_result_gets_a_report(
    weld_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Regression of issue 24: the report was refused ("no cylinder") after the result file
    had been written; it is now made for a known point like for any target."""
    output, report_dir = tmp_path / "result.yaml", tmp_path / "report"
    code = main(
        [
            "calibrate",
            str(weld_bag),
            "--target",
            "known_point",
            "--initial",
            str(weld_bag / "initial.yaml"),
            "--output",
            str(output),
            "--report",
            str(report_dir),
        ]
    )
    assert code == 0, capsys.readouterr().err
    text = (report_dir / "index.html").read_text(encoding="utf-8")
    point = yaml.safe_load(output.read_text(encoding="utf-8"))["known_point"]["point"]
    assert "known point target" in text
    assert "[" + ", ".join(f"{v * 1e3:+.3f}" for v in point) + "] mm" in text
    assert (report_dir / "profiles_3d.png").stat().st_size > 1000
