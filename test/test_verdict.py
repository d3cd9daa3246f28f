"""Issue 30: a verdict a user can act on (good / use with care / do not use, the deciding
reason and the next step), the same in the summary, the result file and the report; a
refused run says so first; warnings one line each with their stable id; grouped rejections
and counts of the profiles recorded."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from linelaser_calib.cli import main
from linelaser_calib.core.forked import available_workers
from linelaser_calib.core.pipeline import Method
from linelaser_calib.core.regions import PER_POSE, PLAIN, ModelChoice
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.types import Level, Rejection
from linelaser_calib.core.verdict import OTHER, WARNING_KINDS, judge, warning_kind
from linelaser_calib.io import read_truth_yaml
from linelaser_calib.io.bags.read import read_bag
from linelaser_calib.io.results import read_result_yaml, write_result_yaml
from linelaser_calib.offline import calibrate_bag
from linelaser_calib.settings import Front, pipeline_config, render_warnings
from linelaser_calib.sim.bag_writer import simulate_to_bag
from linelaser_calib.summary import (
    format_summary,
    model_text,
    rejection_lines,
    samples_line,
    truth_error,
)

ROOT = Path(__file__).resolve().parents[1]
BAGS = ROOT / "bags"
GUIDE = ROOT / "docs" / "quality_and_warnings.md"


def calibrate(
    bag: Path, out: Path, capsys: pytest.CaptureFixture[str], *flags: str
) -> tuple[CalibrationResult, str]:
    """Calibrate ``bag`` through the command line; the result read back and the summary."""
    assert main(["calibrate", str(bag), "--output", str(out), *flags]) == 0
    return read_result_yaml(out), capsys.readouterr().out


@pytest.fixture(scope="module")
def good() -> CalibrationResult:
    """bags/ur_scancontrol calibrated, its verdict judged as the command line does."""
    config = pipeline_config("cylinder", Method.DEFAULT, {}, Front.CLI, workers=available_workers())
    result = calibrate_bag(BAGS / "ur_scancontrol", config).result
    render_warnings(result, Front.CLI)
    return result


def test_a_good_run_says_good_and_export_first(good: CalibrationResult, tmp_path: Path) -> None:
    """bags/ur_scancontrol: the error against the truth is within 3σ on every axis (the
    benches' bound; one recording's axes all within 1σ is a one-in-three draw), the
    self-check ran: good, with its accuracy in use, and the next step is to export; the
    result file carries the same verdict and reads it back."""
    truth = read_truth_yaml(BAGS / "ur_scancontrol" / "truth.yaml")
    error = truth_error(good.T_flange_sensor, truth.T_flange_sensor)
    assert good.uncertainty_translation_m is not None
    assert np.all(np.abs(error.translation_axes_m) < 3.0 * good.uncertainty_translation_m)
    first = format_summary(good, truth).splitlines()[0]
    assert re.match(r"Verdict: GOOD \(accuracy in use 0\.0\d+ mm RMS\): .* Next: export it", first)
    assert good.verdict is not None and good.verdict.level is Level.GOOD
    out = write_result_yaml(good, tmp_path / "r.yaml")
    written = yaml.safe_load(out.read_text(encoding="utf-8"))["quality"]
    assert written["verdict"] == {
        "level": "good",
        "reason": good.verdict.reason,
        "next_step": good.verdict.next_step,
        "warnings": [],
    }
    assert read_result_yaml(out).verdict == good.verdict


def test_a_doubtful_run_names_the_reason_and_the_motion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """bags/cluttered_camera is 1.4 mm off its truth (2.9σ on an axis): use with care, the
    reason a weak direction and the next step the motion its warning names; each warning on
    one line with its id, its place in the result file and its paragraph in the guide."""
    result, text = calibrate(BAGS / "cluttered_camera", tmp_path / "r.yaml", capsys)
    lines = text.splitlines()
    assert lines[0].startswith("Verdict: USE WITH CARE (accuracy in use ")
    assert "weakly determined" in lines[0]
    assert "Next: add poses that translate the sensor across the cylinder axis" in lines[0]
    assert result.verdict is not None and result.verdict.level is Level.USE_WITH_CARE
    for k, warning in enumerate(result.warnings):
        kind = warning_kind(warning).id
        assert result.verdict.warning_ids[k] == kind
        assert lines[1 + k].endswith(
            f"(quality.warnings[{k}]; docs/quality_and_warnings.md#{kind})"
        )
    assert "note grazing-trimmed: trimmed the grazing-angle ends" in text


def test_without_a_self_check_there_is_no_good_and_the_reason_is_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """9 poses are too few for the self-check (10): use with care, why, in the summary, the
    result file and the report; the next step asks for the missing pose."""
    bag, _ = simulate_to_bag(tmp_path / "bag", "ur_scancontrol", 0, {"n_poses": 9})
    report = tmp_path / "report"
    result, text = calibrate(bag, tmp_path / "r.yaml", capsys, "--report", str(report))
    why = "9 samples were used and the self-check needs at least 10"
    assert text.startswith(
        f"Verdict: USE WITH CARE (accuracy in use not measured): not checked: {why}"
    )
    assert "Next: add at least 1 more pose" in text.splitlines()[0]
    assert f"Self-check: not run: {why}" in text
    quality = yaml.safe_load((tmp_path / "r.yaml").read_text(encoding="utf-8"))["quality"]
    assert quality["accuracy_in_use_m"] is None
    assert quality["accuracy_in_use"]["not_measured_because"].startswith(why)
    assert result.verdict is not None and result.verdict.not_measured_because.startswith(why)
    page = (report / "index.html").read_text(encoding="utf-8")
    assert '<div class="verdict use_with_care">' in page and why in page


def test_a_refused_run_says_do_not_use_first_and_counts_every_recorded_profile(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A continuous scan with the default speed gate: refused (exit 1, nothing written); its
    one paragraph opens with the verdict, and the count is of every profile recorded."""
    bag, _ = simulate_to_bag(tmp_path / "bag", "continuous", 0, {"n_poses": 12})
    recorded = len(read_bag(bag).profiles)
    out = tmp_path / "r.yaml"
    assert main(["calibrate", str(bag), "--output", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(
        "linelaser-calib: error: refused, no result was written (verdict: do not use): "
    )
    assert err.count("\n") == 1
    assert re.search(rf"only \d+ of {recorded} recorded profiles", err)
    assert not out.exists()


def test_the_verdict_weighs_each_warning_by_its_kind(good: CalibrationResult) -> None:
    """A failed solve decides do not use over any other warning; a note keeps good; a
    warning no kind describes is not known to be harmless."""
    assert judge(good).level is Level.GOOD
    note = "trimmed the grazing-angle ends of 3 of 30 arcs (12 points)"
    stop = "the refinement stopped after 50 iterations without converging; maybe"
    assert judge(replace(good, warnings=[note])).level is Level.GOOD
    both = judge(replace(good, warnings=["weak hand-eye direction (x): y", stop]))
    assert both.level is Level.DO_NOT_USE and both.reason.startswith("the refinement stopped")
    odd = judge(replace(good, warnings=["something new"]))
    assert odd.level is Level.USE_WITH_CARE and odd.warning_ids == (OTHER.id,)


def test_rejections_are_grouped_by_kind_with_the_recorded_count() -> None:
    """Ten short arcs of different lengths are one line with their count; the profile count
    is of every profile recorded."""
    rejected = [Rejection(i, 0, "ellipse", f"arc too short ({10 + i} deg)") for i in range(10)]
    rejected.append(Rejection(40, 0, "pairing", "no flange pose within 5 ms"))
    result = CalibrationResult(
        np.eye(4),
        None,
        "default",
        list(range(11, 40)),
        rejected,
        1e-5,  # type: ignore[arg-type]
    )
    assert rejection_lines(result) == [
        "10 profiles: arc too short (at ellipse; #0, 1, 2, 3, 4, 5, 6, 7, 8, 9)",
        "1 profile: no flange pose within 5 ms (at pairing; #40)",
    ]
    assert samples_line(result) == "Profiles: 29 used of 40 recorded, 11 rejected"


def test_every_warning_kind_has_its_paragraph_in_the_guide() -> None:
    """Each id is an anchor of docs/quality_and_warnings.md, and the warning quoted there
    (numbers as N) is recognised as that kind."""
    text = GUIDE.read_text(encoding="utf-8")
    quoted = dict(re.findall(r'<a id="([a-z-]+)"></a>`[a-z-]+`(?: \(note\))?: \*\*"([^"]+)"', text))
    for kind in WARNING_KINDS:
        assert kind.id in quoted, kind.id
        example = re.sub(r"\bN\b", "3", quoted[kind.id]).replace("... ", "x ")
        assert warning_kind(example) is kind, (kind.id, example)
    assert f"`{OTHER.id}`" in text


def test_the_model_row_says_when_the_lower_figure_is_not_significant() -> None:
    """Issue 30: 'per-pose ... chosen by the accuracy in use (0.2392 vs 0.2210 mm)' claimed to
    choose the worse number; the choice is a paired test, and the row says so."""
    kept = model_text(ModelChoice(PER_POSE, {PER_POSE: 2.392e-4, PLAIN: 2.210e-4}))
    assert "kept: the plain fit's lower figure is not significantly better" in kept
    assert "0.2392 mm" in kept and "0.2210 mm" in kept
    assert model_text(ModelChoice(PLAIN, {PER_POSE: 2.4e-4, PLAIN: 1.2e-4})).startswith(
        "plain fit, better beyond chance"
    )
