"""A live /calibrate on a long session: a few thousand samples of a continuous sweep, through
the calibration service as the collector would hand them over, against the offline pipeline
on the same recording: the same hand-eye, each profile's features extracted once by each."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from ros_helpers import ServiceUnderTest, init_context, new_domain_id
from std_msgs.msg import Float64MultiArray

from linelaser_calib.core.forked import available_workers
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import run_pipeline
from linelaser_calib.core.targets.cylinder.target import CylinderTarget
from linelaser_calib.core.types import FlangePose, Profile, Sample
from linelaser_calib.io import read_result_yaml
from linelaser_calib.nodes.calibration_service import PARAMETERS
from linelaser_calib.nodes.clock_offset import offset_message
from linelaser_calib.nodes.common import CLOCK_OFFSET_TOPIC, latched_qos
from linelaser_calib.nodes.live_calibration import pipeline_config
from linelaser_calib.sim import simulate
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.summary import truth_error

pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: An 18 s sweep of a 200 Hz profiler (100 points) on an arm at 50 mm/s and 0.3 rad/s: 3,638
#: profiles, 59 neighbourhoods of flange poses; 5 kept per neighbourhood (288) keep the test
#: short.
SWEEP = {
    "n_poses": 3,
    "profile_rate_hz": 200.0,
    "move_speed_m_s": 0.05,
    "move_angular_speed_rad_s": 0.3,
    "resolution": 100,
    "latency_s": 0.0,
}
PER_NEIGHBOURHOOD = 5
#: The collector in continuous mode: the speed gate open.
PAIRING = PairingConfig(max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)


def axes(T_estimate: np.ndarray, T_reference: np.ndarray) -> np.ndarray:
    """Per-axis difference of two hand-eyes, as their 1σ: rotation (rad), translation (m)."""
    difference = truth_error(T_estimate, T_reference)
    return np.concatenate([difference.rotation_axes_rad, difference.translation_axes_m])


def test_a_long_session_calibrates_live_in_the_time_offline_takes(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    extracted: list[list[int]] = []  # the profiles of each extraction of the cylinder's features
    extract = CylinderTarget.extract

    def counted(target: CylinderTarget, samples: list[Sample], *args: Any, **kwargs: Any) -> Any:
        extracted.append([s.index for s in samples])
        return extract(target, samples, *args, **kwargs)

    monkeypatch.setattr(CylinderTarget, "extract", counted)
    data = simulate(scenario_from_preset("continuous", **SWEEP), seed=3)
    samples = pair_profiles(data.profiles, data.poses, PAIRING).samples
    assert len(samples) > 3000
    output = tmp_path / "hand_eye.yaml"
    domain = new_domain_id()
    context = init_context(domain)
    service = ServiceUnderTest(
        context,
        domain,
        output,
        max_samples=5000,
        per_neighbourhood=PER_NEIGHBOURHOOD,
    )
    try:
        offset = service.probe.node.create_publisher(
            Float64MultiArray, CLOCK_OFFSET_TOPIC, latched_qos(1)
        )
        offset.publish(Float64MultiArray(data=offset_message(PAIRING, None)))
        service.send(
            [
                (Profile(s.stamp_ns, s.points, "laser"), FlangePose(s.stamp_ns, s.T_base_flange))
                for s in samples
            ],
            timeout_s=60.0,
        )
        started = time.monotonic()
        answer = service.probe.call("calibrate")
        live_s = time.monotonic() - started
    finally:
        service.close()
        context.try_shutdown()
    assert answer.success, answer.message
    assert "set aside as near-duplicates" in answer.message

    written = read_result_yaml(output)
    quality = yaml.safe_load(output.read_text())["quality"]
    assert quality["thinning"]["samples_given"] == len(samples)
    assert quality["thinning"]["samples_kept"] < len(samples) / 5
    # One extraction, of the profiles kept: each profile's features once per /calibrate.
    assert [len(set(e)) for e in extracted] == [quality["thinning"]["samples_kept"]]
    assert written.pairing == PAIRING  # the collector's pairing travels with the result
    assert "clock_offset_diagnosis" in quality["pairing"]  # the sweep moves: the test ran
    error = axes(written.T_flange_sensor, data.truth.T_flange_sensor)
    assert written.uncertainty_rotation_rad is not None
    assert written.uncertainty_translation_m is not None
    sigma = np.concatenate([written.uncertainty_rotation_rad, written.uncertainty_translation_m])
    assert np.all(np.abs(error) <= 4.0 * sigma), (error, sigma)

    # The command line's pipeline on the same recording (its workers): the same hand-eye.
    values = {spec.name: spec.default for spec in PARAMETERS}
    values["per_neighbourhood"] = PER_NEIGHBOURHOOD
    config = replace(pipeline_config(values), pairing=PAIRING, workers=available_workers())
    started = time.monotonic()
    offline = run_pipeline(data.profiles, data.poses, config)
    offline_s = time.monotonic() - started
    assert len(extracted) == 2 and sorted(extracted[1]) == sorted(extracted[0])
    moved = axes(written.T_flange_sensor, offline.T_flange_sensor)
    assert np.all(np.abs(moved) <= 0.01 * sigma), moved
    assert live_s <= 3.0 * offline_s + 5.0, (live_s, offline_s)
    assert "ellipse:" not in capfd.readouterr().err  # no progress display in a node
