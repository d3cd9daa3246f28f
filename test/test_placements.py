"""Several placements of the target in one joint calibration, and the advice to record them."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from test_joint_calibration import ARM_SEED, held_out_rms_m, recording

from linelaser_calib.cli import main
from linelaser_calib.io.kinematics import read_kinematics
from linelaser_calib.io.results import read_result_yaml

#: The second placement: moved by about 0.5 m and tilted by 27 degrees.
MOVED = ["--cylinder-base", "0.3,-0.35,0", "--axis", "0,0.5,1"]


@pytest.fixture(scope="module")
def placements(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two recordings of the same arm (ARM_SEED), the cylinder upright and then moved."""
    root = tmp_path_factory.mktemp("placements")
    common = ["--scenario", "ur5e_kinematic", "--poses", "16", "--arm-seed", str(ARM_SEED)]
    assert main(["simulate", str(root / "upright"), *common, "--seed", "21"]) == 0
    assert main(["simulate", str(root / "moved"), *common, "--seed", "22", *MOVED]) == 0
    return root / "upright", root / "moved"


def test_two_placements_give_one_hand_eye_and_kinematics_that_map_a_held_out_scan(
    placements: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    upright, moved = placements
    out = tmp_path / "two.yaml"
    argv = ["calibrate", str(upright), str(moved), "--kinematics", "ur5e", "--output", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "calibrated together with 1 more recordings" in printed
    result = read_result_yaml(out)
    corrections = read_kinematics(out)
    assert corrections is not None and len(corrections.corrections) >= 16
    raw = yaml.safe_load(out.read_text(encoding="utf-8"))
    truth = yaml.safe_load((upright / "truth.yaml").read_text(encoding="utf-8"))
    # The result's cylinder is the first recording's.
    assert raw["cylinder"]["point"] == pytest.approx(truth["cylinder"]["point"], abs=5e-4)
    held_out = recording(3, 10, (0.35, -0.2, 0.0))
    assert held_out.truth.arm is not None
    nominal = held_out.truth.arm.nominal
    before = held_out_rms_m(held_out, nominal, held_out.truth.T_flange_sensor)
    after = held_out_rms_m(held_out, corrections.apply(nominal), result.T_flange_sensor)
    assert before > 2e-4
    assert after < 0.5 * before


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--pose-source", "pose"], "calibrated together only by the joint kinematic"),
        (["--kinematics", "ur5e", "--nominal-kinematics"], "calibrated together only by"),
        (["--kinematics", "ur5e", "--method", "paper"], "calibrated together only by"),
    ],
)
def test_several_recordings_are_refused_where_no_joint_calibration_runs(
    placements: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    expected: str,
) -> None:
    upright, moved = placements
    out = tmp_path / "refused.yaml"
    assert main(["calibrate", str(upright), str(moved), *extra, "--output", str(out)]) == 1
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err
    assert not out.exists()
