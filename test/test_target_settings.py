"""Every shared setting either acts on the chosen target and method or is refused, and a model
that does not fit the data is refused instead of written.

The settings are table-driven (each target's ``options``); these tests pin the cases that were
once accepted and silently ignored, through the CLI and the service, and the model-fit checks.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from linelaser_calib.cli import build_parser, main
from linelaser_calib.cli.calibrate import calibrate_config
from linelaser_calib.core.errors import InputError, ModelMismatch
from linelaser_calib.core.pairing import pair_profiles
from linelaser_calib.core.pipeline import PipelineConfig, calibrate_samples
from linelaser_calib.core.targets import all_targets, get_target, target_names
from linelaser_calib.core.targets.base import SETTINGS, configure
from linelaser_calib.core.types import FlangePose, Sample
from linelaser_calib.io import read_bag, write_bag
from linelaser_calib.nodes import calibration_service
from linelaser_calib.settings import Front, render

REPO_ROOT = Path(__file__).resolve().parents[1]
WELD_BAG = REPO_ROOT / "bags" / "weld_seam"
CYLINDER_BAG = REPO_ROOT / "bags" / "ur_scancontrol"
INITIAL = str(WELD_BAG / "initial.yaml")


def calibrate_args(*extra: str) -> Any:
    return build_parser().parse_args(["calibrate", "bag", *extra])


#: (target, method, flags, the refused flag) that were accepted and ignored before.
REFUSED = [
    ("known_point", "default", ["--sensor-sigma", "2e-6"], "--sensor-sigma"),
    ("known_point", "default", ["--radius", "0.02"], "--radius"),
    (
        "known_point",
        "paper",
        ["--robot-sigma-t", "2e-5", "--point", "0.5,0.1,0"],
        "--robot-sigma-t",
    ),
    (
        "known_point",
        "paper",
        ["--robot-sigma-r", "1e-5", "--point", "0.5,0.1,0"],
        "--robot-sigma-r",
    ),
    ("cylinder", "paper", ["--sensor-sigma", "2e-6"], "--sensor-sigma"),
    ("cylinder", "paper", ["--robot-sigma-t", "2e-5"], "--robot-sigma-t"),
    ("cylinder", "paper", ["--robot-sigma-r", "1e-5"], "--robot-sigma-r"),
    ("cylinder", "paper", ["--initial", INITIAL], "--initial"),
    ("cylinder", "default", ["--point", "0.5,0.1,0"], "--point"),
    ("cylinder", "paper", ["--scale", "free"], "--scale"),
    ("sphere", "paper", ["--scale", "free"], "--scale"),
    ("line", "paper", ["--scale", "fixed"], "--scale"),
    ("known_point", "default", ["--scale", "free"], "--scale"),
]


@pytest.mark.parametrize(("target", "method", "flags", "refused"), REFUSED)
def test_a_flag_that_would_be_ignored_is_refused(
    target: str, method: str, flags: list[str], refused: str
) -> None:
    initial = ["--initial", INITIAL] if target == "known_point" else []
    args = calibrate_args("--target", target, "--method", method, *flags, *initial)
    with pytest.raises(InputError, match=rf"^{refused}\b.* would be ignored"):
        calibrate_config(args)


#: (target, flags, config field, value) of settings that were ignored before and act now.
ACTING = [
    ("known_point", ["--robot-sigma-t", "2e-5"], "robot_sigma_t_m", 2e-5),
    ("known_point", ["--robot-sigma-r", "1e-5"], "robot_sigma_r_rad", 1e-5),
    ("known_point", ["--min-samples", "9"], "min_samples", 9),
    ("cylinder", ["--min-samples", "12"], "min_samples", 12),
    ("line", ["--scale", "free"], "scale", "free"),
]


@pytest.mark.parametrize(("target", "flags", "field", "value"), ACTING)
def test_a_flag_that_applies_reaches_the_target_config(
    target: str, flags: list[str], field: str, value: float
) -> None:
    config = calibrate_config(calibrate_args("--target", target, *flags))
    assert getattr(config.target_config, field) == value
    untouched = calibrate_config(calibrate_args("--target", target))
    assert getattr(untouched.target_config, field) != value


def test_cylinder_noise_levels_reach_the_refinement() -> None:
    flags = ["--sensor-sigma", "2e-6", "--robot-sigma-t", "3e-5", "--robot-sigma-r", "1e-5"]
    refine = calibrate_config(calibrate_args(*flags)).target_config.refine
    assert (refine.sensor_sigma_m, refine.robot_sigma_t_m, refine.robot_sigma_r_rad) == (
        2e-6,
        3e-5,
        1e-5,
    )


def test_scale_reaches_the_cylinder_config_and_a_bad_one_is_refused() -> None:
    assert calibrate_config(calibrate_args("--scale", "free")).target_config.scale == "free"
    assert calibrate_config(calibrate_args()).target_config.scale == "auto"
    with pytest.raises(InputError, match="along-line scale must be one of auto, fixed, free"):
        calibrate_config(calibrate_args("--scale", "on"))


def test_refusal_exits_1_on_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["calibrate", str(WELD_BAG), "--target", "known_point", "--sensor-sigma", "2e-6"])
    assert code == 1
    err = capsys.readouterr().err
    assert "--sensor-sigma does not apply to the known point target" in err
    assert "Traceback" not in err


def service_values(**overrides: Any) -> dict[str, Any]:
    values = {spec.name: spec.default for spec in calibration_service.PARAMETERS}
    return {**values, **overrides}


def test_service_refuses_and_applies_its_parameters_per_target() -> None:
    with pytest.raises(InputError, match="radius does not apply to the known point target"):
        calibration_service.pipeline_config(service_values(target="known_point", radius=0.02))
    with pytest.raises(InputError, match="known_point does not apply to the cylinder target"):
        calibration_service.pipeline_config(service_values(known_point=(0.5, 0.1, 0.0)))
    config = calibration_service.pipeline_config(
        service_values(target="known_point", min_samples=9)
    )
    assert config.target_config.min_samples == 9
    default = calibration_service.pipeline_config(service_values(target="known_point"))
    assert default.target_config.min_samples == get_target("known_point").config_type().min_samples


def test_every_target_option_names_a_shared_setting_and_a_config_field() -> None:
    for target in all_targets():
        assert set(target.options) <= set(SETTINGS), target.name
        assert target.name in target_names()
        for name, option in target.options.items():
            if option.field and name != "initial":
                value: object = {
                    "min_samples": 7,
                    "point_m": np.zeros(3),
                    "centre_side": "-y",
                    "scale": "free",
                }.get(name, 0.5)
                for method in option.methods:
                    others = {
                        n: INITIAL if n == "initial" else np.zeros(3)
                        for n, o in target.options.items()
                        if method in o.required_by and n != name
                    }
                    config = configure(target, method, {name: value, **others}, {})
                    head, *rest = option.field.split(".")
                    found = getattr(config, head)
                    for part in rest:
                        found = getattr(found, part)
                    assert np.all(found == value), (target.name, name)


# -- the model-fit check ---------------------------------------------------------------------


def paired_samples(bag: Path) -> list[Sample]:
    contents = read_bag(bag)
    return pair_profiles(contents.profiles, contents.poses, PipelineConfig().pairing).samples


def test_known_point_refuses_views_of_a_moving_point() -> None:
    """A seam scanned along its length (each view sees another point) is not a known point:
    the residual is orders of magnitude above the robot's noise, and no result is made."""
    samples = paired_samples(WELD_BAG)
    moved = []
    for j, s in enumerate(samples):
        T = s.T_base_flange.copy()
        T[:3, 3] += np.array([0.004 * j, 0.0, 0.0])  # the seam point moves 4 mm per view
        moved.append(Sample(s.index, s.stamp_ns, T, s.points))
    config = PipelineConfig(target="known_point")
    assert calibrate_samples(samples, config).rms_residual_m < 1e-3
    with pytest.raises(
        ModelMismatch, match=r"known point model does not explain .*{setting:target\} line"
    ):
        calibrate_samples(moved, config)


def test_cylinder_refuses_arcs_of_varying_radius(tmp_path: Path) -> None:
    """Cuts of a sphere are circles of varying radius; a cylinder's all share its radius."""
    samples = paired_samples(CYLINDER_BAG)
    scaled = [
        Sample(s.index, s.stamp_ns, s.T_base_flange, s.points * (0.5 + j / len(samples)))
        for j, s in enumerate(samples)
    ]
    assert calibrate_samples(samples, PipelineConfig()).rms_residual_m < 1e-4
    with pytest.raises(
        ModelMismatch, match="not cuts of one cylinder, though each is an elliptical arc"
    ):
        calibrate_samples(scaled, PipelineConfig())


def test_a_model_that_does_not_fit_exits_1_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The known point on a seam whose point moves 5 mm/s under the sensor (as when a seam is
    scanned along its length): exit 1 with the likely causes, no result file."""
    contents = read_bag(WELD_BAG)
    t0 = contents.poses[0].stamp_ns
    moved = []
    for pose in contents.poses:
        T = pose.T_base_flange.copy()
        T[:3, 3] += np.array([0.005 * (pose.stamp_ns - t0) * 1e-9, 0.0, 0.0])
        moved.append(FlangePose(pose.stamp_ns, T, pose.frame_id))
    bag = write_bag(tmp_path / "moving", contents.profiles, moved)
    out = tmp_path / "result.yaml"
    args = ["calibrate", str(bag), "--target", "known_point", "--output", str(out)]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "does not fit" in err and "another target" in err and "Traceback" not in err
    assert not out.exists()


def test_every_registered_target_has_every_member_of_the_protocol() -> None:
    """The registry loads targets by module path, so the type checker cannot see them."""
    from linelaser_calib.core.targets import REGISTRY, get_target
    from linelaser_calib.core.targets.base import Target

    members = {
        name for name in (*Target.__annotations__, *vars(Target)) if not name.startswith("_")
    }
    for name in REGISTRY:
        target = get_target(name)
        missing = sorted(m for m in members if not hasattr(target, m))
        assert not missing, f"target {name} lacks {missing}"
        assert target.name == name


def test_profiles_taken_in_motion_are_counted_together_with_advice() -> None:
    """A continuous scan calibrated with the step-and-shoot speed gate: the error says how to
    calibrate a scan in motion instead of listing each speed apart."""
    from linelaser_calib.core.targets.base import rejection_digest
    from linelaser_calib.core.types import Rejection

    rejections = [
        Rejection(k, k, "pairing", f"robot moving at {30 + k:.1f} mm/s during the profile")
        for k in range(5)
    ] + [Rejection(9, 9, "pairing", "robot rotating at 0.71 deg/s during the profile")]
    digest = render(rejection_digest(rejections), Front.CLI)
    assert digest.startswith("Rejected: 6 x pairing: robot moving or turning during the profile.")
    assert "--max-speed 0 --max-angular-speed 0 and --clock-offset auto" in digest
    assert "--max-speed" not in rejection_digest([Rejection(1, 1, "ellipse", "x")])
