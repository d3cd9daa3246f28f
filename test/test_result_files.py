"""linelaser_calib.io.results: result and truth YAML layout, exact round trips, atomic writes."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    matrix_from_quaternion_xyzw,
    transform_from_rotvec_translation,
)
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.sigma_budget import PROFILE_SCATTER, SHARED_ROBOT_ERROR, SigmaBudget
from linelaser_calib.core.targets.cylinder import CylinderSection
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.types import Rejection
from linelaser_calib.io import (
    ResultFileError,
    read_result_yaml,
    read_truth_yaml,
    write_result_yaml,
    write_truth_yaml,
)


def random_cylinder(rng: np.random.Generator) -> Cylinder:
    direction = rng.normal(size=3)
    return Cylinder(
        rng.normal(size=3), direction / np.linalg.norm(direction), 0.02 + 0.01 * rng.random()
    )


def random_budget(rng: np.random.Generator) -> SigmaBudget:
    """A noise model's 1σ widened by two named factors per axis."""
    return SigmaBudget(
        np.r_[rng.random(3) * 1e-3, rng.random(3) * 1e-4],
        ((PROFILE_SCATTER, 1.0 + rng.random(6)), (SHARED_ROBOT_ERROR, 1.0 + rng.random(6))),
    )


def random_result(rng: np.random.Generator, *, with_uncertainty: bool = True) -> CalibrationResult:
    budget = random_budget(rng) if with_uncertainty else None
    return CalibrationResult(
        T_flange_sensor=transform_from_rotvec_translation(
            rng.normal(size=3), 0.1 * rng.normal(size=3)
        ),
        target=CylinderSection(
            random_cylinder(rng),
            radius_estimated=True,
            noise_levels={"sensor_sigma_m": 5e-6, "robot_sigma_t_m": 1.2e-4},
        ),
        method="default",
        samples_used=[0, 1, 2, 4, 7],
        samples_rejected=[
            Rejection(3, 1_700_000_000_000_000_003, "ellipse", "arc 12.0 deg is too short"),
            Rejection(5, 1_700_000_000_000_000_005, "pairing", "no pose within 5.0 ms"),
        ],
        rms_residual_m=float(rng.random() * 1e-4),
        sample_residuals_m={i: float(rng.random() * 1e-4) for i in (0, 1, 2, 4, 7)},
        uncertainty_translation_m=None if budget is None else budget.sigma[3:],
        uncertainty_rotation_rad=None if budget is None else budget.sigma[:3],
        sigma_budget=budget,
        warnings=["rotation about the sensor x axis is weakly observed"],
        history={"refine_cost": [3.0, 2.0, 1.0]},
        clock_offset_live_s=-0.004 + 1e-4 * float(rng.normal()) if with_uncertainty else None,
        clock_offset_live_sigma_s=1e-4 if with_uncertainty else None,
    )


def test_result_file_follows_the_contract(tmp_path: Path) -> None:
    result = random_result(np.random.default_rng(30))
    path = write_result_yaml(result, tmp_path / "out" / "result.yaml")
    text = path.read_text()
    assert "!!" not in text  # plain YAML, no python/numpy tags
    data = yaml.safe_load(text)
    assert list(data) == ["hand_eye", "cylinder", "quality"]
    hand_eye = data["hand_eye"]
    assert (hand_eye["parent_frame"], hand_eye["child_frame"]) == ("tool0", "laser")
    T = np.eye(4)
    T[:3, :3] = matrix_from_quaternion_xyzw(hand_eye["rotation_xyzw"])
    T[:3, 3] = hand_eye["translation"]
    np.testing.assert_allclose(T, result.T_flange_sensor, atol=1e-15)
    np.testing.assert_array_equal(hand_eye["matrix"], result.T_flange_sensor)
    assert hand_eye["matrix"][3] == [0.0, 0.0, 0.0, 1.0]
    assert set(hand_eye["uncertainty"]) == {"translation_m", "rotation_rad"}
    assert data["cylinder"]["frame"] == "base_link"
    assert set(data["cylinder"]) == {"frame", "point", "direction", "radius"}
    quality = data["quality"]
    assert quality["samples_used"] == 5
    assert quality["samples_rejected"][0] == {
        "index": 3,
        "stamp_ns": 1_700_000_000_000_000_003,
        "stage": "ellipse",
        "reason": "arc 12.0 deg is too short",
    }
    assert {"method", "rms_residual_m", "warnings"} <= set(quality)
    assert type(quality["rms_residual_m"]) is float


def test_result_round_trips_exactly(tmp_path: Path) -> None:
    rng = np.random.default_rng(31)
    for i in range(5):
        result = random_result(rng, with_uncertainty=i % 2 == 0)
        back = read_result_yaml(write_result_yaml(result, tmp_path / f"r{i}.yaml"))
        np.testing.assert_allclose(back.T_flange_sensor, result.T_flange_sensor, atol=1e-15)
        np.testing.assert_array_equal(back.target.cylinder.point, result.target.cylinder.point)
        np.testing.assert_allclose(
            back.target.cylinder.direction, result.target.cylinder.direction, atol=1e-16
        )
        assert back.target.cylinder.radius == result.target.cylinder.radius
        assert back.samples_used == result.samples_used
        assert back.samples_rejected == result.samples_rejected
        assert back.rms_residual_m == result.rms_residual_m
        assert back.sample_residuals_m == result.sample_residuals_m
        assert back.warnings == result.warnings
        assert back.target.radius_estimated is True
        assert back.target.noise_levels == result.target.noise_levels
        assert back.clock_offset_live_s == result.clock_offset_live_s
        assert back.clock_offset_live_sigma_s == result.clock_offset_live_sigma_s
        assert (back.method, back.parent_frame, back.child_frame, back.base_frame) == (
            "default",
            "tool0",
            "laser",
            "base_link",
        )
        if result.uncertainty_translation_m is None:
            assert back.uncertainty_translation_m is None
            assert back.uncertainty_rotation_rad is None
            assert back.sigma_budget is None
        else:
            assert back.sigma_budget is not None and result.sigma_budget is not None
            assert [n for n, _ in back.sigma_budget.factors] == [
                PROFILE_SCATTER,
                SHARED_ROBOT_ERROR,
            ]
            np.testing.assert_allclose(
                back.sigma_budget.total, result.sigma_budget.total, rtol=1e-12
            )
            np.testing.assert_allclose(
                back.sigma_budget.sigma[3:], back.uncertainty_translation_m, rtol=1e-15
            )
            np.testing.assert_array_equal(
                back.uncertainty_translation_m, result.uncertainty_translation_m
            )
            np.testing.assert_array_equal(
                back.uncertainty_rotation_rad, result.uncertainty_rotation_rad
            )


@pytest.mark.parametrize("correlation", [None, -0.97])
def test_estimated_along_line_scale_round_trips(tmp_path: Path, correlation: float | None) -> None:
    rng = np.random.default_rng(34)
    result = random_result(rng)
    section = CylinderSection(
        random_cylinder(rng),
        radius_estimated=correlation is not None,
        scale=0.0049,
        scale_sigma=2.5e-5,
        scale_radius_correlation=correlation,
    )
    path = write_result_yaml(replace(result, target=section), tmp_path / "result.yaml")
    cylinder = yaml.safe_load(path.read_text())["cylinder"]
    assert cylinder["along_line_scale"] == pytest.approx(1.0049, abs=1e-12)
    assert cylinder["along_line_scale_sigma"] == 2.5e-5
    assert cylinder.get("along_line_scale_radius_correlation") == correlation
    back = read_result_yaml(path).target
    assert isinstance(back, CylinderSection)
    assert back.scale == pytest.approx(0.0049, abs=1e-12)
    assert (back.scale_sigma, back.scale_radius_correlation) == (2.5e-5, correlation)
    assert "scale 1.00490 ± 0.00003 (+0.490 ± 0.003 %" in back.describe("base_link")
    # Without an estimated scale the section keeps its four keys and reads back without one.
    plain = read_result_yaml(write_result_yaml(result, tmp_path / "plain.yaml")).target
    assert isinstance(plain, CylinderSection) and plain.scale is None


def test_missing_uncertainty_is_written_as_null(tmp_path: Path) -> None:
    result = random_result(np.random.default_rng(32), with_uncertainty=False)
    path = write_result_yaml(result, tmp_path / "result.yaml")
    assert yaml.safe_load(path.read_text())["hand_eye"]["uncertainty"] is None
    assert "uncertainty: null" in path.read_text()


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(33)
    path = write_result_yaml(random_result(rng), tmp_path / "result.yaml")
    before = path.read_bytes()

    def failing_replace(src: str, dst: str) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(ResultFileError, match=r"cannot write .*result.yaml.*No space left"):
        write_result_yaml(random_result(rng), path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["result.yaml"]


def test_truth_round_trips_with_plain_extras(tmp_path: Path) -> None:
    rng = np.random.default_rng(34)
    T = transform_from_rotvec_translation(rng.normal(size=3), rng.normal(size=3))
    cylinder = random_cylinder(rng)
    extra = {
        "scenario": "nominal",
        "seed": np.int64(7),
        "noise": {"sigma_m": np.float32(2e-5)},
        "poses": np.arange(3),
    }
    path = write_truth_yaml(
        tmp_path / "truth.yaml", T, CylinderSection(cylinder), base_frame="world", extra=extra
    )
    assert "!!" not in path.read_text()
    truth = read_truth_yaml(path)
    np.testing.assert_allclose(truth.T_flange_sensor, T, atol=1e-15)
    np.testing.assert_array_equal(truth.target.cylinder.point, cylinder.point)
    assert truth.target.cylinder.radius == cylinder.radius
    assert (truth.parent_frame, truth.child_frame, truth.base_frame) == ("tool0", "laser", "world")
    assert truth.raw["seed"] == 7 and truth.raw["poses"] == [0, 1, 2]
    assert truth.raw["noise"]["sigma_m"] == float(np.float32(2e-5))
    assert "uncertainty" not in truth.raw["hand_eye"] and "quality" not in truth.raw


def test_truth_extras_cannot_replace_the_truth_or_hold_objects(tmp_path: Path) -> None:
    cylinder = CylinderSection(Cylinder(np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.02))
    with pytest.raises(InputError, match="overwrite the truth"):
        write_truth_yaml(tmp_path / "t.yaml", np.eye(4), cylinder, extra={"cylinder": 1})
    with pytest.raises(InputError, match="not plain YAML data"):
        write_truth_yaml(tmp_path / "t.yaml", np.eye(4), cylinder, extra={"when": object()})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("edit", "expected_text"),
    [
        (None, "does not exist"),
        ("hand_eye: [unclosed\n", "is not valid YAML"),
        ("- 1\n- 2\n", "the top level must be a mapping"),
        ("delete hand_eye.translation", "key hand_eye.translation is missing"),
        (
            "set hand_eye.translation [1, 2]",
            "key hand_eye.translation must be finite numbers of shape",
        ),
        (
            "set hand_eye.rotation_xyzw [0, 0, 0, 0]",
            "hand_eye.rotation_xyzw [0.0, 0.0, 0.0, 0.0] (xyzw) has norm 0.000000",
        ),
        ("set hand_eye.rotation_xyzw [0, 0, a, 1]", "key hand_eye.rotation_xyzw must be numbers"),
        ("set hand_eye.translation [0.5, 0, 0]", "hand_eye.matrix disagrees"),
        ("set cylinder.radius 0", "radius > 0 m"),
        ("set cylinder.along_line_scale -1", "key along_line_scale must be a ratio > 0"),
        ("set cylinder.along_line_scale wide", "key along_line_scale must be a finite number"),
        ("set quality.rms_residual_m fast", "key quality.rms_residual_m must be a number"),
        (
            "set quality.line_noise {white_sigma_m: 1.0e-6, smooth_sigma_m: 4.0e-6, length_m: -1}",
            "key quality.line_noise: line noise: smooth σ >= 0, depth σ >= 0 and length > 0 needed",
        ),
        ("set quality.line_noise {white_sigma_m: 1.0e-6}", "key quality.line_noise needs"),
        ("set quality.line_noise [1, 2]", "key quality.line_noise must be a mapping"),
        ("delete quality", "key quality is missing"),
        (
            "set quality.sigma_budget.widened_by {luck: {rotation: [1, 1, 1]}}",
            "key quality.sigma_budget.widened_by.luck is no widening of the 1 sigma",
        ),
    ],
)
def test_malformed_result_files_raise_result_file_error(
    tmp_path: Path, edit: str | None, expected_text: str
) -> None:
    path = tmp_path / "result.yaml"
    if edit is not None:
        write_result_yaml(random_result(np.random.default_rng(35)), path)
        data = yaml.safe_load(path.read_text())
        action, _, rest = edit.partition(" ")
        if action in {"delete", "set"}:
            dotted, _, value = rest.partition(" ")
            *parents, leaf = dotted.split(".")
            section = data
            for key in parents:
                section = section[key]
            if action == "delete":
                del section[leaf]
            else:
                section[leaf] = yaml.safe_load(value)
            path.write_text(yaml.safe_dump(data))
        else:
            path.write_text(edit)
    with pytest.raises(ResultFileError) as caught:
        read_result_yaml(path)
    assert expected_text in str(caught.value)
    assert str(path) in str(caught.value)


@pytest.mark.parametrize(
    "section",
    [
        {"model": "no_such_robot", "corrections": {}},
        {"model": "ur5e", "corrections": {"no_such_joint.d": 1e-4}},
        {"model": "ur5e", "corrections": [1, 2]},
        {"corrections": {}},
    ],
)
def test_truth_with_unusable_arm_kinematics_compares_with_the_physical_hand_eye(
    tmp_path: Path, section: dict[str, object]
) -> None:
    """A truth file's kinematics section only refines the comparison: one that cannot be used
    leaves the physical hand-eye, without an error."""
    from linelaser_calib.summary import hand_eye_seen

    rng = np.random.default_rng(35)
    T = transform_from_rotvec_translation(rng.normal(size=3), rng.normal(size=3))
    path = write_truth_yaml(
        tmp_path / "truth.yaml",
        T,
        CylinderSection(random_cylinder(rng)),
        extra={"kinematics": section},
    )
    truth = read_truth_yaml(path)
    np.testing.assert_allclose(hand_eye_seen(truth), truth.T_flange_sensor, atol=0.0)
