"""The HTML report, the CLI's summary, JSON and progress output, and core.residuals.

A small simulated bag (12 poses of the paper's scene, with its truth.yaml) is calibrated once
per method; the report's pages and figures are checked for completeness and against the
result and the simulator's truth. The page is also rendered in headless Chromium when it is
installed (skipped otherwise). Every target's committed bag gets a report through the
command line, checked against its truth; a run that fails writes none of its outputs.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image
from scipy.spatial.transform import Rotation

from linelaser_calib.cli import main
from linelaser_calib.core.geometry import (
    apply_transform,
    invert_transform,
    orthonormal_basis,
    quaternion_xyzw_from_matrix,
    transform_error,
    transform_from_translation_quaternion,
)
from linelaser_calib.core.pipeline import Method, PipelineConfig
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.base import surface_map
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.targets.cylinder.residuals import (
    cylinder_coordinates,
    sample_centre_distances,
    sample_surface_residuals,
)
from linelaser_calib.core.targets.sphere.section import SphereSection
from linelaser_calib.core.types import Rejection, SampleFit
from linelaser_calib.io import Truth, read_truth_yaml
from linelaser_calib.offline import calibrate_bag
from linelaser_calib.report import write_report
from linelaser_calib.report.data import report_data
from linelaser_calib.sim import scenario_from_preset, simulate
from linelaser_calib.sim.bag_writer import simulate_to_bag
from linelaser_calib.summary import format_summary

CHROMIUM = Path("/usr/bin/chromium")
#: The figures issue #6 asks for, by file name.
EXPECTED_FIGURES = {
    "centre_distances.png",
    "point_residuals.png",
    "profiles_3d.png",
    "residual_map.png",
    "convergence.png",
}
#: The self-check's figure, in a report of a result with a self-check.
SELF_CHECK_FIGURE = "self_check.png"
SMALL: dict[str, object] = {"n_poses": 12, "resolution": 200}


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated bag with its truth.yaml."""
    path, _ = simulate_to_bag(tmp_path_factory.mktemp("sim") / "bag", "paper", 3, SMALL)
    return path


@pytest.fixture(scope="module")
def truth(bag: Path) -> Truth:
    return read_truth_yaml(bag / "truth.yaml")


@pytest.fixture(scope="module", params=[Method.DEFAULT, Method.PAPER], ids=lambda m: m.value)
def result(request: pytest.FixtureRequest, bag: Path) -> CalibrationResult:
    return calibrate_bag(bag, PipelineConfig(method=request.param)).result


@pytest.fixture(scope="module")
def report(
    tmp_path_factory: pytest.TempPathFactory, result: CalibrationResult, truth: Truth, bag: Path
) -> Path:
    out = tmp_path_factory.mktemp(f"report_{result.method}") / "report"
    return write_report(out, result, inputs=[("bag", str(bag))], truth=truth)


def image_sources(page: Path) -> list[str]:
    return re.findall(r'<img src="([^"]+)"', page.read_text(encoding="utf-8"))


def with_rejection_and_warning(result: CalibrationResult) -> CalibrationResult:
    return replace(
        result,
        samples_rejected=[Rejection(5, 0, "ellipse", "arc too short <1 mm> & thin")],
        warnings=["poses weak & <odd>"],
    )


# --- core.residuals -------------------------------------------------------------------------


def test_cylinder_coordinates_recover_known_points() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        cylinder = Cylinder(rng.normal(size=3), direction, float(rng.uniform(0.005, 0.05)))
        u, v = orthonormal_basis(direction)
        angle = rng.uniform(-np.pi, np.pi, 50)
        along = rng.uniform(-0.1, 0.1, 50)
        offset = rng.normal(scale=1e-4, size=50)
        radial = np.cos(angle)[:, None] * u + np.sin(angle)[:, None] * v
        points = (
            cylinder.point
            + along[:, None] * direction
            + (cylinder.radius + offset)[:, None] * radial
        )
        c = cylinder_coordinates(points, cylinder)
        np.testing.assert_allclose(c.angle_rad, angle, atol=1e-9)
        np.testing.assert_allclose(c.along_m, along, atol=1e-12)
        np.testing.assert_allclose(c.residual_m, offset, atol=1e-12)


def test_residuals_vanish_for_the_true_calibration_and_true_poses() -> None:
    """Noise-free simulated points and true flange poses lie on the true cylinder."""
    scenario = scenario_from_preset("paper", **SMALL)
    truth = simulate(scenario, 4).truth
    T_sensor_flange = invert_transform(truth.T_flange_sensor)
    fits = []
    for k, T_base_flange in enumerate(truth.T_base_flange_true):
        points = truth.points_true_sensor[k]
        points = points[np.all(np.isfinite(points), axis=1)]
        # The ellipse centre is where the axis crosses the laser plane y = 0.
        T_sensor_base = T_sensor_flange @ invert_transform(T_base_flange)
        c = apply_transform(T_sensor_base, truth.cylinder.point)
        d = T_sensor_base[:3, :3] @ truth.cylinder.direction
        centre = c - c[1] / d[1] * d
        fits.append(SampleFit(k, 0, T_base_flange, points, centre[[0, 2]]))
    residuals = sample_surface_residuals(fits, truth.T_flange_sensor, truth.cylinder)
    assert max(float(np.max(np.abs(r))) for r in residuals) < 1e-9
    distances = sample_centre_distances(fits, truth.T_flange_sensor, truth.cylinder)
    assert distances.shape == (len(fits),)
    assert float(np.max(distances)) < 1e-9


def test_report_residuals_agree_with_the_pipeline(result: CalibrationResult) -> None:
    data = report_data(result)
    assert list(data.indices) == result.samples_used
    if result.method == "paper":
        # The paper method's residual is this very centre-to-axis distance.
        expected = [result.sample_residuals_m[i] for i in data.indices]
        np.testing.assert_allclose(data.feature_distances_m, expected, rtol=1e-9, atol=1e-12)
    else:
        # With the recorded poses the residual also holds the robot's pose error (0.1 mm).
        assert result.rms_residual_m < data.recorded_pose_rms_m < 5e-4
    assert len(data.all_distances_m) == sum(len(f.points) for f in result.sample_fits)
    assert data.surface is not None
    # The unrolled map measures along the axis from the first scanned point, whichever way
    # the fitted direction points: 0 to the scanned length, never negative.
    assert float(np.min(data.surface.along)) == 0.0
    along = (data.all_points_base - result.target.cylinder.point) @ result.target.cylinder.direction
    assert float(np.max(data.surface.along)) == pytest.approx(float(np.ptp(along)), rel=1e-9)


# --- the HTML page --------------------------------------------------------------------------


def expected_figures(result: CalibrationResult) -> set[str]:
    return EXPECTED_FIGURES | ({SELF_CHECK_FIGURE} if result.self_check is not None else set())


def check_figures(page: Path, expected: set[str]) -> None:
    """Every expected figure is referenced relatively and is a decodable, non-empty PNG."""
    sources = image_sources(page)
    assert set(sources) == expected
    assert len(sources) == len(expected)
    for source in sources:
        png = page.parent / source
        assert png.stat().st_size > 1000
        with Image.open(png) as image:
            assert image.format == "PNG"
            image.load()
            assert image.width >= 800 and image.height >= 300
            assert np.asarray(image.convert("L")).std() > 5.0  # not blank


def test_report_shows_every_figure_and_is_self_contained(
    report: Path, result: CalibrationResult, tmp_path: Path
) -> None:
    text = report.read_text(encoding="utf-8")
    assert "http" not in text and 'src="/' not in text and "file:" not in text
    check_figures(report, expected_figures(result))
    copy = tmp_path / "copied"
    shutil.copytree(report.parent, copy)
    check_figures(copy / report.name, expected_figures(result))


def test_report_states_the_result(
    report: Path, result: CalibrationResult, truth: Truth, bag: Path
) -> None:
    text = report.read_text(encoding="utf-8")
    T = result.T_flange_sensor
    for value in T[:3, 3] * 1e3:
        assert f"{value:+.3f}" in text
    for value in Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True):
        assert f"{value:+.4f}" in text
    for value in quaternion_xyzw_from_matrix(T[:3, :3]):
        assert f"{value:+.6f}" in text
    assert "fixed axes x-y-z" in text
    assert str(bag) in text
    assert f"{result.target.cylinder.radius * 1e3:.3f} mm" in text
    n = len(result.samples_used)
    assert f"Profiles: {n} used of {n} recorded, 0 rejected" in text
    rotation, translation = transform_error(T, truth.T_flange_sensor)
    assert "Error against truth" in text
    assert f"{np.degrees(rotation):.4f} deg" in text
    assert f"{translation * 1e3:.4f} mm" in text
    if result.method == "default":
        assert "1 sigma translation" in text
        assert result.self_check is not None and result.self_check.accuracy_in_use_m is not None
        accuracy = f"{result.self_check.accuracy_in_use_m * 1e3:.4f} mm RMS"
        assert text.index("<h1>") < text.index(accuracy) < text.index("<h2>")
    else:
        assert "not estimated by the paper method" in text


def test_report_lists_rejections_and_warnings_escaped(
    result: CalibrationResult, tmp_path: Path
) -> None:
    page = write_report(tmp_path / "report", with_rejection_and_warning(result))
    text = page.read_text(encoding="utf-8")
    assert "1 profile: arc too short &lt;1 mm&gt; &amp; thin (at ellipse; #5)" in text
    assert "poses weak &amp; &lt;odd&gt;" in text
    assert "Error against truth" not in text


@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs /usr/bin/chromium")
def test_report_renders_in_headless_chromium(report: Path, tmp_path: Path) -> None:
    shot = tmp_path / "shot.png"
    subprocess.run(
        [
            str(CHROMIUM),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={tmp_path / 'profile'}",
            f"--screenshot={shot}",
            "--window-size=1200,3000",
            report.resolve().as_uri(),
        ],
        capture_output=True,
        timeout=120,
        check=True,
    )
    with Image.open(shot) as image:
        assert image.size == (1200, 3000)
        rgb = np.asarray(image.convert("RGB")).astype(int)
    # The first figure's stems are matplotlib's default blue (31, 119, 180): present only if
    # the PNGs loaded from their relative paths.
    blue = np.all(np.abs(rgb - [31, 119, 180]) < 30, axis=2)
    assert blue.sum() > 500


# --- CLI output -----------------------------------------------------------------------------


def test_summary_has_everything_issue_6_asks_for(result: CalibrationResult, truth: Truth) -> None:
    text = format_summary(with_rejection_and_warning(result), truth)
    T = result.T_flange_sensor
    assert "translation" in text and f"{T[0, 3] * 1e3:+.3f}" in text
    rpy = Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True)
    assert f"[{rpy[0]:+.4f}, {rpy[1]:+.4f}, {rpy[2]:+.4f}] deg" in text
    assert "fixed axes x-y-z, R = Rz(yaw) Ry(pitch) Rx(roll)" in text
    q = quaternion_xyzw_from_matrix(T[:3, :3])
    assert "rotation_xyzw" in text and f"{q[3]:+.6f}" in text
    assert "1 sigma" in text
    assert f"rms {result.rms_residual_m * 1e6:.1f} um" in text
    assert "per-sample residual" in text and "median" in text
    used = len(result.samples_used)
    assert f"Profiles: {used} used of {used + 1} recorded, 1 rejected" in text
    assert "1 profile: arc too short <1 mm> & thin (at ellipse; #5)" in text
    assert "warning other-warnings: poses weak & <odd> (quality.warnings[0]; " in text
    assert "Error against truth" in text


def test_summary_of_a_thousand_profiles_shows_the_distribution_and_the_worst(
    result: CalibrationResult, truth: Truth
) -> None:
    """Issue 24: a summary lists no residual per profile; a 1,000-profile one fits 80 lines."""
    rng = np.random.default_rng(24)
    residuals = {i: float(v) for i, v in enumerate(rng.uniform(3e-6, 6e-6, 1000))}
    residuals[777] = 50e-6
    residuals[123] = 40e-6
    rejected = [Rejection(1000 + k, 0, "pairing", f"reason {k % 3}") for k in range(200)]
    big = replace(
        result,
        samples_used=list(residuals),
        sample_residuals_m=residuals,
        samples_rejected=rejected,
    )
    text = format_summary(big, truth)
    assert len(text.splitlines()) <= 80
    values = np.array(list(residuals.values())) * 1e6
    assert f"median {np.median(values):.1f}" in text
    assert f"95% {np.percentile(values, 95):.1f}" in text
    assert f"min {values.min():.1f}" in text and "max 50.0 um" in text
    assert "#777 50.0, #123 40.0, " in text
    assert "Profiles: 1000 used of 1200 recorded, 200 rejected" in text


def test_truth_in_other_frames_is_not_compared(result: CalibrationResult, truth: Truth) -> None:
    """Issue 24: --flange-frame flange on a bag whose truth is tool0 -> laser printed a
    120 deg "error"; hand-eyes of different frames are not compared, and the summary says
    why."""
    assert truth.parent_frame == "tool0"
    text = format_summary(replace(result, parent_frame="flange"), truth)
    assert "not compared" in text and "flange -> laser" in text and "tool0 -> laser" in text
    assert "largest error/sigma" not in text and "rotation per axis" not in text
    assert "rotation per axis" in format_summary(result, truth)


def test_json_gives_the_same_result_as_the_yaml(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    output = tmp_path / "result.yaml"
    assert main(["calibrate", str(bag), "--json", "--output", str(output)]) == 0
    printed = json.loads(capsys.readouterr().out)
    written = json.loads(json.dumps(yaml.safe_load(output.read_text(encoding="utf-8"))))
    assert printed == written
    assert printed["hand_eye"]["parent_frame"] == "tool0"


def test_progress_is_on_for_a_terminal_and_off_otherwise(
    bag: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["calibrate", str(bag), "--method", "paper"]) == 0
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(["calibrate", str(bag), "--method", "paper"]) == 0
    err = capsys.readouterr().err
    for stage in ("reading", "pairing", "ellipse", "global solve"):
        assert f"] {stage}: " in err
    assert main(["calibrate", str(bag), "--method", "paper", "--no-progress"]) == 0
    assert capsys.readouterr().err == ""


def test_cli_writes_report_and_viz(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report_dir, viz = tmp_path / "report", tmp_path / "viz.mcap"
    argv = ["calibrate", str(bag), "--method", "paper", "--report", str(report_dir)]
    assert main([*argv, "--viz", str(viz)]) == 0
    out = capsys.readouterr().out
    assert f"Wrote {report_dir / 'index.html'}" in out
    assert f"Wrote {viz}" in out
    check_figures(report_dir / "index.html", EXPECTED_FIGURES)
    assert viz.stat().st_size > 0


def test_report_puts_the_verdict_first_and_names_each_residual(
    report: Path, result: CalibrationResult, tmp_path: Path
) -> None:
    text = report.read_text(encoding="utf-8")
    assert text.index("verdict") < text.index("Hand-eye T_flange_sensor")
    # No good without a self-check (the paper method has none).
    level = "good" if result.self_check is not None else "use_with_care"
    assert f'<div class="verdict {level}">' in text
    assert f"<td>{level.replace('_', ' ').upper()}</td>" in text
    if result.self_check is not None:
        assert f"{result.self_check.accuracy_in_use_m * 1e3:.4f} mm RMS" in text
    for name in ("fit residual", "recorded-pose residual", "feature residual"):
        assert f"<th>{name}</th>" in text
    assert f"{result.rms_residual_m * 1e6:.1f} um RMS" in text
    warned = write_report(tmp_path / "warned", with_rejection_and_warning(result))
    page = warned.read_text(encoding="utf-8")
    assert '<div class="verdict use_with_care">' in page and "<td>USE WITH CARE</td>" in page
    assert "poses weak &amp; &lt;odd&gt;" in page


# --- every target's committed bag -------------------------------------------------------

#: Per target: the committed bag and flags of its guide, and the figures of its report.
COMMON_FIGURES = {"point_residuals.png", "profiles_3d.png", SELF_CHECK_FIGURE, "convergence.png"}
TARGET_RUNS = {
    "cylinder": (["bags/paper"], EXPECTED_FIGURES | {SELF_CHECK_FIGURE}),
    "sphere": (["bags/sphere", "--target", "sphere"], COMMON_FIGURES | {"residual_map.png"}),
    "line": (
        [
            "bags/line",
            "--target",
            "line",
            "--max-speed",
            "0",
            "--max-angular-speed",
            "0",
            "--clock-offset",
            "auto",
        ],
        COMMON_FIGURES | {"clock_offset.png"},
    ),
    "known_point": (
        ["bags/weld_seam", "--target", "known_point", "--initial", "bags/weld_seam/initial.yaml"],
        COMMON_FIGURES,
    ),
}
REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("target", sorted(TARGET_RUNS))
def test_every_target_gets_a_report(
    target: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv, figures = TARGET_RUNS[target]
    bag = REPO / argv[0]
    output, report_dir = tmp_path / "result.yaml", tmp_path / "report"
    flags = [str(REPO / a) if a.startswith("bags/") else a for a in argv[1:]]
    code = main(
        ["calibrate", str(bag), *flags, "--output", str(output), "--report", str(report_dir)]
    )
    assert code == 0, capsys.readouterr().err
    page = report_dir / "index.html"
    assert f"Wrote {page}" in capsys.readouterr().out
    text = page.read_text(encoding="utf-8")
    title = get_target(target).title
    assert f"<h1>Line-laser hand-eye calibration: {title} target</h1>" in text
    check_figures(page, figures)
    written = yaml.safe_load(output.read_text(encoding="utf-8"))
    assert f"{written['quality']['accuracy_in_use_m'] * 1e3:.4f} mm RMS" in text
    # The target in the base frame, as the result file holds it.
    assert target in written and "<h2>The " + title + " and the residuals</h2>" in text
    # Against the simulator's truth: the page shows the hand-eye's error, and it is small.
    truth = read_truth_yaml(bag / "truth.yaml")
    estimate = transform_from_translation_quaternion(
        written["hand_eye"]["translation"], written["hand_eye"]["rotation_xyzw"]
    )
    rotation, translation = transform_error(estimate, truth.T_flange_sensor)
    assert f"{translation * 1e3:.4f} mm" in text and f"{np.degrees(rotation):.4f} deg" in text
    assert translation < 5e-4 and rotation < np.radians(0.1)
    # Issue 30: how far an initial hand-eye was corrected, where one was given.
    assert ("initial corrected by" in text) == ("--initial" in argv)


def test_figures_mark_rejections_offset_flat_costs_and_scale_axes_alike(
    result: CalibrationResult,
) -> None:
    """Issue 30: a rejected profile is marked, not a silent gap; a cost that barely changes
    is drawn as its change from the final value; one mm is as long on every 3-D axis."""
    from linelaser_calib.report.figures import (
        convergence_figure,
        profiles_3d_figure,
        sample_residual_figure,
    )

    data = report_data(with_rejection_and_warning(result))
    labels = [c.get_label() for c in sample_residual_figure(data).axes[0].collections]
    assert any(label.startswith("rejected (1;") for label in labels)
    flat = replace(result, history={"refine_cost": [3104.67013, 3104.67001, 3104.67]})
    line = convergence_figure(report_data(flat)).axes[0].lines[0]
    assert np.allclose(line.get_ydata(), [1.3e-4, 1e-5, 0.0], atol=1e-9)
    ax = profiles_3d_figure(data).axes[0]
    spans = [np.ptp(limits) for limits in (ax.get_xlim(), ax.get_ylim(), ax.get_zlim())]
    assert np.allclose(ax.get_box_aspect() / np.max(ax.get_box_aspect()), spans / np.max(spans))


# --- a failed run writes nothing ----------------------------------------------------------


def leftovers(directory: Path, keep: set[str]) -> set[str]:
    return {p.name for p in directory.iterdir()} - keep


def test_a_refused_calibration_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    output = tmp_path / "result.yaml"
    output.write_bytes(b"hand_eye: earlier result\n")
    report_dir, viz = tmp_path / "report", tmp_path / "viz.mcap"
    argv = ["calibrate", str(REPO / "bags/line"), "--target", "line", "--max-speed", "0"]
    argv += ["--max-angular-speed", "0", "--output", str(output)]
    # Without --clock-offset auto the sweep's 12 ms latency bends the seam: refused.
    assert main([*argv, "--report", str(report_dir), "--viz", str(viz)]) == 1
    err = capsys.readouterr().err
    assert "does not fit" in err and "Traceback" not in err
    assert output.read_bytes() == b"hand_eye: earlier result\n"
    assert leftovers(tmp_path, {"result.yaml"}) == set()


def test_a_report_that_cannot_be_made_is_refused_before_solving(
    tmp_path: Path, bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    output = tmp_path / "result.yaml"
    output.write_bytes(b"earlier\n")
    argv = ["calibrate", str(bag), "--method", "paper", "--output", str(output)]
    assert main([*argv, "--report", str(tmp_path / "missing" / "report")]) == 1
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "taken").write_text("a file")
    assert main([*argv, "--report", str(tmp_path / "taken")]) == 1
    assert "it is an existing file" in capsys.readouterr().err
    assert output.read_bytes() == b"earlier\n"
    assert leftovers(tmp_path, {"result.yaml", "taken"}) == set()


def test_a_report_that_fails_while_written_leaves_the_earlier_result(
    tmp_path: Path, bag: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import linelaser_calib.report.figures as figures

    def disk_full(data: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(figures, "profiles_3d_figure", disk_full)
    output, report_dir, viz = tmp_path / "result.yaml", tmp_path / "report", tmp_path / "v.mcap"
    output.write_bytes(b"earlier\n")
    argv = ["calibrate", str(bag), "--method", "paper", "--output", str(output)]
    assert main([*argv, "--report", str(report_dir), "--viz", str(viz)]) == 1
    err = capsys.readouterr().err
    assert "cannot write the report" in err and "No space left on device" in err
    assert output.read_bytes() == b"earlier\n"
    assert leftovers(tmp_path, {"result.yaml"}) == set()
    # An earlier report directory keeps its files too.
    report_dir.mkdir()
    (report_dir / "index.html").write_text("earlier report")
    assert main([*argv, "--report", str(report_dir)]) == 1
    assert (report_dir / "index.html").read_text() == "earlier report"
    assert leftovers(report_dir, {"index.html"}) == set()
    assert leftovers(tmp_path, {"result.yaml", "report"}) == set()


def test_sphere_surface_map_recovers_longitude_and_latitude() -> None:
    rng = np.random.default_rng(7)
    longitude = rng.uniform(-np.pi, np.pi, 50)
    latitude = rng.uniform(-1.5, 1.5, 50)
    centre, radius = np.array([0.4, -0.2, 0.1]), 0.025
    points = centre + radius * np.column_stack(
        [
            np.cos(latitude) * np.cos(longitude),
            np.cos(latitude) * np.sin(longitude),
            np.sin(latitude),
        ]
    )
    section = SphereSection(centre, radius, 1, radius_estimated=False, side_estimated=False)
    mapped = surface_map(section, points)
    assert mapped is not None and mapped.along_unit == "rad"
    np.testing.assert_allclose(mapped.across, longitude, atol=1e-12)
    np.testing.assert_allclose(mapped.along, latitude, atol=1e-12)


def test_the_error_against_truth_is_also_given_where_the_points_are(
    result: CalibrationResult, truth: Truth
) -> None:
    """Issue 30: a hand-eye turned 0.1 deg about the measuring centre (100 mm along the
    sensor z) moves the sensor origin by 0.175 mm, the points not at all; the summary says
    both."""
    turn = np.eye(4)
    turn[:3, :3] = Rotation.from_rotvec([np.radians(0.1), 0.0, 0.0]).as_matrix()
    centre = np.eye(4)
    centre[2, 3] = 0.1
    T = truth.T_flange_sensor @ centre @ turn @ np.linalg.inv(centre)
    text = format_summary(replace(result, T_flange_sensor=T, measuring_centre_depth_m=0.1), truth)
    origin = float(re.search(r"  translation +([\d.]+) mm", text).group(1))  # type: ignore[union-attr]
    points = float(re.search(r"at the points +([\d.]+) mm", text).group(1))  # type: ignore[union-attr]
    assert origin == pytest.approx(100.0 * np.radians(0.1), abs=1e-3)
    assert points < 1e-4
