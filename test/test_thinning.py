"""The near-duplicate rule (core/thinning.py): at most N samples per neighbourhood of flange
poses, evenly spaced in time, said in the result file and the summary; one setting."""

from __future__ import annotations

import numpy as np
import pytest

from linelaser_calib.cli import build_parser
from linelaser_calib.cli.calibrate import calibrate_config
from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import transform_from_rotvec_translation
from linelaser_calib.core.pipeline import PipelineConfig
from linelaser_calib.core.regions import CLUSTER_ANGLE_RAD, CLUSTER_RADIUS_M
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.cylinder import CylinderSection
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.thinning import DEFAULT_PER_NEIGHBOURHOOD, thin_samples
from linelaser_calib.core.types import Sample
from linelaser_calib.io.results import result_to_dict
from linelaser_calib.summary import format_summary, one_line_summary

#: Three flange poses 0.3 m and 30 deg apart (6 and 3.75 neighbourhoods: each a cell of
#: its own, well inside it), each visited in 4 passes of 25 samples.
CENTRES = [
    transform_from_rotvec_translation(np.radians([180.0, 0.0, 10.0]), [0.0, 0.0, 0.5])
    @ transform_from_rotvec_translation(np.radians([30.0 * k, 0.0, 0.0]), [0.3 * k, 0.0, 0.0])
    for k in range(3)
]
PASSES, PER_PASS = 4, 25


def sweeps(seed: int = 0) -> list[Sample]:
    """The three poses visited in turn, 4 times, 25 samples a visit, 5 ms apart, each off
    its pose by at most 2 mm and 0.3 deg."""
    rng = np.random.default_rng(seed)
    samples = []
    for _ in range(PASSES):
        for centre in CENTRES:
            for _ in range(PER_PASS):
                jitter = transform_from_rotvec_translation(
                    rng.uniform(-1, 1, 3) * np.radians(0.3), rng.uniform(-1, 1, 3) * 2e-3
                )
                k = len(samples)
                samples.append(Sample(k, k * 5_000_000, centre @ jitter, np.zeros((0, 3))))
    return samples


def test_each_neighbourhood_keeps_its_cap_evenly_spaced_over_its_passes() -> None:
    samples = sweeps()
    kept, thinning = thin_samples(samples, 10)
    assert thinning is not None
    assert (thinning.kept, thinning.total, thinning.neighbourhoods, thinning.thinned) == (
        30,
        300,
        3,
        3,
    )
    assert (thinning.cell_m, thinning.cell_rad) == (CLUSTER_RADIUS_M, CLUSTER_ANGLE_RAD)
    assert [s.index for s in kept] == sorted(s.index for s in kept)
    for c, centre in enumerate(CENTRES):
        mine = [
            s.index for s in kept if np.linalg.norm(s.T_base_flange[:3, 3] - centre[:3, 3]) < 0.01
        ]
        visits = [s.index for s in samples if (s.index // PER_PASS) % len(CENTRES) == c]
        assert len(mine) == 10
        assert (mine[0], mine[-1]) == (visits[0], visits[-1])  # first and last kept
        gaps = np.diff([visits.index(i) for i in mine])  # in the cell's own time order
        assert gaps.max() - gaps.min() <= 1  # evenly spaced
        assert len({visits.index(i) // PER_PASS for i in mine}) == PASSES  # every pass
    chosen = [s.index for s in kept][::2]  # what a clock-offset search kept, say
    again, _ = thin_samples(samples, 10, chosen)
    assert [s.index for s in again] == chosen


def test_nothing_is_set_aside_below_the_cap_nor_with_the_rule_off() -> None:
    samples = sweeps()
    kept, thinning = thin_samples(samples, PASSES * PER_PASS)
    assert kept is samples
    assert thinning is not None and thinning.set_aside == 0 and thinning.sentence() == ""
    assert thin_samples(samples, 0) == (samples, None)


def test_the_result_file_and_the_summary_say_what_was_set_aside() -> None:
    _, thinning = thin_samples(sweeps(), 10)
    result = CalibrationResult(
        T_flange_sensor=np.eye(4),
        target=CylinderSection(Cylinder(np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.02)),
        method="default",
        samples_used=list(range(28)),
        samples_rejected=[],
        rms_residual_m=1e-5,
        thinning=thinning,
    )
    entry = result_to_dict(result)["quality"]["thinning"]
    assert entry == {
        "samples_kept": 30,
        "samples_given": 300,
        "neighbourhoods": 3,
        "neighbourhoods_thinned": 3,
        "per_neighbourhood": 10,
        "cell_m": CLUSTER_RADIUS_M,
        "cell_rad": pytest.approx(np.radians(8.0)),
    }
    summary = format_summary(result)
    assert "Profiles: 28 used of 298 recorded, 0 rejected, 270 set aside as near-duplicates" in (
        summary
    )
    assert "3 of the 3 neighbourhoods of flange poses (50 mm x 8 deg cells)" in summary
    assert "28 of 300 samples used (270 set aside as near-duplicates)" in one_line_summary(
        result, 300
    )


def test_one_setting_turns_it_off_or_sets_the_cap() -> None:
    def config(*extra: str) -> PipelineConfig:
        return calibrate_config(build_parser().parse_args(["calibrate", "bag", *extra]))

    assert config().per_neighbourhood == DEFAULT_PER_NEIGHBOURHOOD
    assert config("--per-neighbourhood", "0").per_neighbourhood == 0
    assert config("--per-neighbourhood", "7").per_neighbourhood == 7
    with pytest.raises(SystemExit):
        config("--per-neighbourhood", "-1")
    with pytest.raises(InputError, match="whole number"):
        PipelineConfig(per_neighbourhood=-3)
