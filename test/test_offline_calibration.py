"""Offline calibration of simulated bags against truth: both methods, any names and sizes."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from linelaser_calib.cli import main
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.latency import CLOCK_OFFSET_CODE
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pipeline import PipelineConfig
from linelaser_calib.core.targets.cylinder import CylinderSection
from linelaser_calib.core.targets.cylinder import target as cylinder_target
from linelaser_calib.core.targets.cylinder.features import fit_samples
from linelaser_calib.io.results import read_result_yaml, read_truth_yaml, result_to_dict
from linelaser_calib.offline import calibrate_bag

BAGS = Path(__file__).resolve().parent.parent / "bags"

#: Bounds on the hand-eye error (deg, mm) per method, well above what each method reaches at
#: the committed bags' noise (bench/accuracy.py gives the measured RMS).
BOUNDS = {"paper": (1.5, 2.0), "default": (0.02, 0.1)}


@pytest.mark.parametrize("method", ["paper", "default"])
@pytest.mark.parametrize("bag", ["paper", "ur_scancontrol"])
def test_committed_bag_recovers_truth(bag: str, method: str, tmp_path: Path) -> None:
    out = tmp_path / "result.yaml"
    assert main(["calibrate", str(BAGS / bag), "--method", method, "--output", str(out)]) == 0
    result, truth = read_result_yaml(out), read_truth_yaml(BAGS / bag / "truth.yaml")
    rot, trans = transform_error(result.T_flange_sensor, truth.T_flange_sensor)
    max_deg, max_mm = BOUNDS[method]
    assert np.degrees(rot) < max_deg and trans * 1e3 < max_mm
    assert isinstance(result.target, CylinderSection)
    assert result.target.cylinder.radius == pytest.approx(truth.target.cylinder.radius, abs=2e-4)
    assert abs(result.target.cylinder.direction @ truth.target.cylinder.direction) > np.cos(
        np.radians(1.0)
    )
    if method == "default":
        assert result.uncertainty_translation_m is not None
        assert np.all(result.uncertainty_translation_m < 1e-3)


def test_other_names_radius_and_axis(tmp_path: Path) -> None:
    bag = tmp_path / "custom"
    args = ["simulate", str(bag), "--scenario", "paper", "--seed", "11", "--poses", "20"]
    args += ["--points", "300", "--radius", "0.03", "--profile-topic", "/scanner/cloud"]
    args += ["--pose-topic", "/robot/tcp", "--sensor-frame", "scanner", "--base-frame", "world"]
    assert main(args) == 0
    out = tmp_path / "result.yaml"
    assert main(["calibrate", str(bag), "--flange-frame", "flange", "--output", str(out)]) == 0
    result, truth = read_result_yaml(out), read_truth_yaml(bag / "truth.yaml")
    assert (result.parent_frame, result.child_frame, result.base_frame) == (
        "flange",
        "scanner",
        "world",
    )
    rot, trans = transform_error(result.T_flange_sensor, truth.T_flange_sensor)
    assert np.degrees(rot) < 0.05 and trans < 1e-4
    assert isinstance(result.target, CylinderSection)
    assert result.target.cylinder.radius == pytest.approx(0.03, abs=1e-4)
    assert main(["calibrate", str(bag), "--radius", "0.03", "--output", str(out)]) == 0
    assert read_result_yaml(out).target.cylinder.radius == 0.03


@pytest.fixture(scope="module")
def continuous(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A continuous scan (4 ms profile latency) and its calibration with the gate open and the
    true clock offset given."""
    bag = tmp_path_factory.mktemp("continuous") / "continuous"
    assert main(["simulate", str(bag), "--scenario", "continuous", "--seed", "3"]) == 0
    out = bag.parent / "result.yaml"
    args = ["calibrate", str(bag), *OPEN_GATE, "--clock-offset", "-0.004", "--output", str(out)]
    assert main(args) == 0
    return bag, out


#: The speed gate opened, for a scan in motion.
OPEN_GATE = ["--max-speed", "0", "--max-angular-speed", "0"]


def test_continuous_motion_needs_the_speed_gate_opened_and_the_latency(
    continuous: tuple[Path, Path], tmp_path: Path
) -> None:
    """Continuous scanning (4 ms profile latency): rejected as moving by default; with the
    gate open and the clock offset given, the hand-eye is recovered."""
    bag, result = continuous
    truth = read_truth_yaml(bag / "truth.yaml")
    assert main(["calibrate", str(bag), "--output", str(tmp_path / "result.yaml")]) == 1
    rot, trans = transform_error(read_result_yaml(result).T_flange_sensor, truth.T_flange_sensor)
    assert np.degrees(rot) < 0.05 and trans < 1e-4


def test_a_clock_offset_left_out_is_named_before_the_robot(continuous: tuple[Path, Path]) -> None:
    """The residual follows the flange's velocity: without the 4 ms offset the first warning
    names the clock and about 4 ms; with the true offset given the test finds nothing."""
    bag, given = continuous
    pairing = PairingConfig(max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)
    forgotten = calibrate_bag(bag, PipelineConfig(pairing=pairing, self_check_folds=0)).result
    assert forgotten.clock_diagnosis is not None and forgotten.clock_diagnosis.significant
    assert forgotten.clock_diagnosis.offset_s == pytest.approx(-0.004, abs=1e-3)
    assert forgotten.warnings[0].startswith("the clocks look offset by about -")
    assert "{setting:clock_offset_s} auto" in forgotten.warnings[0]
    section = result_to_dict(forgotten)["quality"]["pairing"]["clock_offset_diagnosis"]
    assert section["code"] == CLOCK_OFFSET_CODE
    written = yaml.safe_load(given.read_text(encoding="utf-8"))["quality"]
    assert not written["pairing"]["clock_offset_diagnosis"]["significant"]
    assert not any("clocks look offset" in w for w in written["warnings"])


def test_reconstruct_pairs_as_the_calibration_did(
    continuous: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """quality.pairing travels with the result: reconstruct maps every profile of the scan in
    motion the calibration used, and says how many and with what pairing; a flag given
    overrides it and the profiles left out are counted with the reason."""
    bag, result = continuous
    pairing = read_result_yaml(result).pairing
    assert pairing is not None and pairing.max_linear_speed_m_s == 0.0
    assert pairing.clock_offset_s == -0.004
    out = tmp_path / "cloud.ply"
    assert main(["reconstruct", str(bag), "--calibration", str(result), "--output", str(out)]) == 0
    text = capsys.readouterr().out
    n = len(read_result_yaml(result).samples_used) + len(read_result_yaml(result).samples_rejected)
    assert f": {n} of {n} profiles mapped" in text
    assert "paired with the calibration's pairing: no speed gate" in text
    args = ["reconstruct", str(bag), "--calibration", str(result), "--max-speed", "0.005"]
    assert main([*args, "--output", str(tmp_path / "gated.ply")]) == 0
    text = capsys.readouterr().out
    assert "--max-speed as given" in text and "x pairing: robot moving" in text


def test_clock_offset_is_estimated_for_continuous_scanning(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """--clock-offset auto finds the 4 ms profile latency and gives the accuracy of the true
    offset, fitting each profile's ellipse once (the search's are used again at the offset
    found); a step-and-shoot bag keeps 0 (nothing moves during a profile)."""
    bag = tmp_path / "continuous"
    assert main(["simulate", str(bag), "--scenario", "continuous", "--seed", "5"]) == 0
    fitted: list[int] = []

    def counted(samples: list[Any], *args: Any, **kwargs: Any) -> Any:
        fitted.extend(s.index for s in samples)
        return fit_samples(samples, *args, **kwargs)

    monkeypatch.setattr(cylinder_target, "fit_samples", counted)
    out = tmp_path / "result.yaml"
    args = ["calibrate", str(bag), "--max-speed", "0", "--max-angular-speed", "0"]
    assert main([*args, "--clock-offset", "auto", "--output", str(out)]) == 0
    assert fitted and len(fitted) == len(set(fitted))
    result = read_result_yaml(out)
    assert result.clock_offset_estimated
    assert result.clock_offset_s == pytest.approx(-0.004, abs=2e-4)
    truth = read_truth_yaml(bag / "truth.yaml")
    rot, trans = transform_error(result.T_flange_sensor, truth.T_flange_sensor)
    assert np.degrees(rot) < 0.05 and trans < 1e-4
    step = BAGS / "ur_scancontrol"
    assert main(["calibrate", str(step), "--clock-offset", "auto", "--output", str(out)]) == 0
    assert read_result_yaml(out).clock_offset_s == 0.0


def test_robot_and_sensor_priors_reach_the_refinement(tmp_path: Path) -> None:
    """bags/ur_scancontrol was simulated with a 0.03 mm / 0.003 deg robot and an 8 um sensor;
    giving those priors instead of the UR-class defaults makes the estimate better."""
    bag, out = BAGS / "ur_scancontrol", tmp_path / "result.yaml"
    truth = read_truth_yaml(bag / "truth.yaml").T_flange_sensor
    assert main(["calibrate", str(bag), "--output", str(out)]) == 0
    _, default_error = transform_error(read_result_yaml(out).T_flange_sensor, truth)
    priors = ["--robot-sigma-t", "3e-5", "--robot-sigma-r", str(np.radians(0.003))]
    priors += ["--sensor-sigma", "8e-6"]
    assert main(["calibrate", str(bag), *priors, "--output", str(out)]) == 0
    _, matched_error = transform_error(read_result_yaml(out).T_flange_sensor, truth)
    assert matched_error < default_error
    with pytest.raises(SystemExit):
        main(["calibrate", str(bag), "--max-speed", "-1"])
