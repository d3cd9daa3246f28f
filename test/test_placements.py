"""Several placements of the target in one joint calibration, and the advice to record them."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_joint_calibration import ARM_SEED, held_out_rms_m, recording

from linelaser_calib.cli import main
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import PipelineConfig, calibrate_samples
from linelaser_calib.core.robot.joint_calibration import KinematicSetup
from linelaser_calib.core.targets.cylinder import CylinderConfig
from linelaser_calib.core.targets.cylinder.advice import placement_advice, thinned
from linelaser_calib.core.targets.cylinder.identifiability import CylinderScan
from linelaser_calib.io.kinematics import read_kinematics
from linelaser_calib.io.results import read_result_yaml
from linelaser_calib.sim import SimulatedData, Surface, scenario_from_preset, simulate

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
    # The placement advice judges both placements together (it covered one only before).
    assert "2 placements of the cylinder determine" in printed
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


def cylinder_scan(data: SimulatedData) -> CylinderScan:
    """The recording's true cylinder points (30 per profile) with its joint vectors."""
    truth = data.truth
    assert truth.joint_positions is not None
    points = [
        p[s == Surface.SIDE] for p, s in zip(truth.points_true_sensor, truth.surface, strict=True)
    ]
    return thinned(CylinderScan(truth.joint_positions, points, truth.cylinder), 30)


def test_advice_asks_for_a_second_placement_that_a_real_one_confirms() -> None:
    """Six poses of one placement leave combinations free that another placement determines:
    the advice says so, and a real second recording of the same arm confirms it."""
    one = recording(31, 6, (0.45, 0.15, 0.0))
    assert one.truth.arm is not None
    model, T = one.truth.arm.nominal, one.truth.T_flange_sensor
    advice = placement_advice(model, [cylinder_scan(one)], T)
    assert advice.best is not None and advice.best.added > 0
    assert advice.needed >= 2 and advice.identifiable < 16
    assert "placements are needed" in advice.text() and "record again" in advice.text()
    moved = simulate(
        scenario_from_preset(
            "ur5e_kinematic",
            n_poses=6,
            kinematic_seed=ARM_SEED,
            cylinder_base_m=(0.3, -0.35, 0.0),
            axis_direction=(0.0, 0.5, 1.0),
        ),
        32,
    )
    both = placement_advice(model, [cylinder_scan(one), cylinder_scan(moved)], T)
    assert both.identifiable > advice.identifiable


def test_advice_on_a_full_recording_says_no_placement_adds_a_parameter() -> None:
    """30 poses determine 16 of 24: the rest is the base's placement, the last link and the
    parallel axes, which no cylinder placement fixes."""
    data = recording(33, 30, (0.45, 0.15, 0.0))
    assert data.truth.arm is not None
    advice = placement_advice(
        data.truth.arm.nominal, [cylinder_scan(data)], data.truth.T_flange_sensor
    )
    assert advice.identifiable == 16 and advice.needed == 1
    assert advice.best is not None and advice.best.added == 0 and advice.best.gain > 1.4
    assert "known_point" in advice.text()


def test_plan_with_kinematics_says_how_many_placements_are_needed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Six poses: the plan asks for a second placement; the calibration's summary too."""
    bag = tmp_path / "few"
    common = ["--scenario", "ur5e_kinematic", "--poses", "6", "--arm-seed", str(ARM_SEED)]
    assert main(["simulate", str(bag), *common, "--seed", "31"]) == 0
    out = tmp_path / "few.yaml"
    argv = ["calibrate", str(bag), "--kinematics", "ur5e", "--min-samples", "6"]
    assert main([*argv, "--output", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "placements are needed" in printed
    argv = ["plan", str(bag), "--from", str(out), "--kinematics", "ur5e", "--n", "2"]
    assert main([*argv, "--axial-range", "0.02,0.1"]) == 0
    (line,) = [x for x in capsys.readouterr().out.splitlines() if x.startswith("Placements: ")]
    assert "2 placements are needed" in line and "record again" in line
    assert (
        main(["plan", str(bag), "--from", str(out), "--kinematics", "ur5e", "--target", "sphere"])
        == 1
    )
    assert "--target cylinder" in capsys.readouterr().err


def test_recordings_of_another_sensor_are_refused(
    placements: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    upright, _ = placements
    other = tmp_path / "other_sensor"
    common = ["--scenario", "ur5e_kinematic", "--poses", "6", "--arm-seed", str(ARM_SEED)]
    assert main(["simulate", str(other), *common, "--sensor-frame", "scanner", *MOVED]) == 0
    out = tmp_path / "refused.yaml"
    argv = ["calibrate", str(upright), str(other), "--kinematics", "ur5e", "--output", str(out)]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "sensor frame 'scanner'" in err and "same sensor on the same arm" in err
    assert not out.exists()


def test_profiles_another_recording_lost_are_named_in_the_result() -> None:
    """A second recording's profiles without an ellipse are left out with a warning that
    says how many and why; before, only the first recording's losses were reported."""
    first = recording(31, 16, (0.45, 0.15, 0.0))
    second = recording(32, 16, (0.35, -0.25, 0.0))
    assert first.truth.arm is not None and first.joint_states is not None
    assert second.joint_states is not None
    samples = [pair_profiles(d.profiles, d.poses, PairingConfig()).samples for d in (first, second)]
    # Three profiles of the second recording hold only a few points: no ellipse.
    broken = [replace(s, points=s.points[:4]) if k < 3 else s for k, s in enumerate(samples[1])]
    nominal = first.truth.arm.nominal
    config = PipelineConfig(
        target_config=CylinderConfig(radius_m=0.02),
        kinematics=KinematicSetup(nominal, first.joint_states),
        self_check_folds=0,
    )
    result = calibrate_samples(
        samples[0], config, placements=[(broken, KinematicSetup(nominal, second.joint_states))]
    )
    (note,) = [w for w in result.warnings if w.startswith("recording 2:")]
    assert "3 of its 16 paired profiles gave no feature" in note
    assert "Rejected: 3 x cleaning" in note
    assert np.all(np.isfinite(result.T_flange_sensor))
