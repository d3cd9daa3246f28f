"""Node logic: pairing, validation and counting in the collector, the service's sample store,
summary and pipeline configuration, parameter files against the declarations, and the
calibrate service's answers in-process."""

from __future__ import annotations

import importlib.util
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from _compare import assert_floats_close
from geometry_msgs.msg import PoseStamped
from rclpy.context import Context
from rclpy.parameter import Parameter
from ros_helpers import (
    REPO_ROOT,
    RosProbe,
    ServiceUnderTest,
    init_context,
    new_domain_id,
    reliable_qos,
    wait_for,
)
from scipy.spatial.transform import Rotation

from linelaser_calib.core.errors import CalibrationError, DegenerateError, InputError
from linelaser_calib.core.geometry import (
    apply_transform,
    invert_transform,
    transform_error,
    transform_from_rotation_translation,
    transform_from_rotvec_translation,
)
from linelaser_calib.core.pairing import NS_PER_S, PairingConfig
from linelaser_calib.core.pipeline import Method, PipelineConfig, validate_sample
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.cylinder import CylinderConfig, CylinderSection
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.targets.cylinder.residuals import axis_extent
from linelaser_calib.core.targets.known_point import KnownPoint, KnownPointConfig, extract_corner
from linelaser_calib.core.types import FlangePose, Profile, Rejection, Sample, SampleFit
from linelaser_calib.io import ResultFileError, SessionBagWriter, read_bag, read_result_yaml
from linelaser_calib.nodes import calibration_service, collector
from linelaser_calib.nodes.clock_offset import ClockOffsetTracker
from linelaser_calib.nodes.collection import (
    KEY_PROFILES_BEFORE,
    KEY_PROFILES_LOST,
    SKIP_BACKLOG,
    SKIP_CANDIDATE,
    SKIP_CLEARED,
    SKIP_MOVING,
    SKIP_NOT_CAPTURED,
    SKIP_RATE,
    SKIP_SAMPLED,
    CollectorConfig,
    LiveCollector,
    Mode,
    reason_key,
)
from linelaser_calib.nodes.common import parameter_values
from linelaser_calib.nodes.sample_store import (
    SampleStore,
    points_in_base,
)
from linelaser_calib.sim import scenario_from_preset, simulate
from linelaser_calib.sim.weld import simulate_weld, weld_scenario_from_preset
from linelaser_calib.summary import one_line_summary

T0 = 1_700_000_000 * NS_PER_S
T_REST = transform_from_rotvec_translation([0.1, -0.2, 0.3], [0.4, 0.1, 0.5])
#: The committed weld-seam bag's old hand-eye and taught point.
WELD_INITIAL = REPO_ROOT / "bags" / "weld_seam" / "initial.yaml"


def ns(t_s: float) -> int:
    return T0 + round(t_s * NS_PER_S)


def resting_poses(start_s: float, stop_s: float, rate_hz: float = 125.0) -> list[FlangePose]:
    """The flange at rest at T_REST, reported at rate_hz."""
    n = round((stop_s - start_s) * rate_hz) + 1
    return [FlangePose(ns(start_s + k / rate_hz), T_REST) for k in range(n)]


def profile(t_s: float) -> Profile:
    return Profile(ns(t_s), np.zeros((4, 3)), frame_id="laser")


class Logged:
    """Collects (key, message) pairs passed to on_new_reason."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, str]] = []

    def __call__(self, key: str, message: str) -> None:
        self.calls.append((key, message))


def make_collector(**config: Any) -> tuple[LiveCollector, Logged]:
    """A collector in ``continuous`` mode unless ``mode`` says otherwise."""
    logged = Logged()
    config.setdefault("mode", Mode.CONTINUOUS)
    return LiveCollector(CollectorConfig(**config), logged), logged


def feed_poses(c: LiveCollector, poses: list[FlangePose], now_s: float = 0.0) -> None:
    for pose in poses:
        c.add_pose(pose, now_s)


def drain(c: LiveCollector, admit: bool = True) -> list[int]:
    """Validate every candidate (admitting or rejecting it), then take the samples to store;
    their profile indices."""
    while (pending := c.next_to_validate()) is not None:
        if admit:
            c.admit(pending)
        else:
            c.reject_validated(
                Rejection(pending.sample.index, pending.sample.stamp_ns, "ellipse", "bad")
            )
    return [p.sample.index for p in c.take_to_store()]


def assert_all_counted(c: LiveCollector) -> None:
    assert c.received == c.accepted + c.rejected.total + c.skipped.total + c.pending


# -- collector logic --------------------------------------------------------------------------


def test_reason_key_replaces_numbers_but_not_names() -> None:
    assert (
        reason_key("pairing", "robot moving at 12.3 mm/s (limit 5.0 mm/s, +1e-3 s)")
        == "pairing: robot moving at # mm/s (limit # mm/s, # s)"
    )
    assert reason_key("message", "PointCloud2 field 'z' is float32") == (
        "message: PointCloud2 field 'z' is float32"
    )


def test_profile_waits_until_the_poses_around_it_arrived() -> None:
    c, _ = make_collector()
    feed_poses(c, resting_poses(0.0, 1.0))
    c.add_profile(profile(0.995), now_s=0.0)
    assert (c.paired, c.pending) == (0, 1)
    feed_poses(c, resting_poses(1.008, 1.024))
    assert (c.paired, c.pending, c.accepted, c.session_samples) == (1, 0, 1, 1)
    (stored,) = c.take_to_store()  # continuous: stored first, checked beside
    assert stored.sample.stamp_ns == ns(0.995)
    np.testing.assert_allclose(stored.sample.T_base_flange, T_REST, atol=1e-12)
    assert (stored.sensor_frame, stored.base_frame) == ("laser", "base_link")
    assert_all_counted(c)


def test_profile_without_poses_is_rejected_after_waiting_the_pose_window() -> None:
    c, logged = make_collector(pose_window_s=1.0)
    c.add_profile(profile(0.0), now_s=100.0)
    c.release(now_s=100.5)
    assert c.pending == 1
    c.release(now_s=101.1)
    assert (c.pending, c.rejected.total) == (0, 1)
    assert logged.calls == [
        ("pairing: no flange pose received", "pairing: no flange pose received")
    ]


def test_each_rejection_reason_is_counted_and_logged_once() -> None:
    c, logged = make_collector()
    feed_poses(c, resting_poses(0.0, 2.0))
    for t in (1.0, 0.5, 0.4, 1.1):  # the 2nd and 3rd go backwards
        c.add_profile(profile(t), now_s=0.0)
    c.reject_profile("PointCloud2 row_step 10 B is inconsistent with width 3")
    c.reject_profile("PointCloud2 row_step 12 B is inconsistent with width 4")
    drain(c)
    counts = c.rejected.counts()
    backwards = [k for k in counts if k.startswith("stamp:")]
    assert len(backwards) == 1 and counts[backwards[0]] == 2
    assert counts["message: PointCloud2 row_step # B is inconsistent with width #"] == 2
    assert len(logged.calls) == 2
    assert logged.calls[1][1] == "message: PointCloud2 row_step 10 B is inconsistent with width 3"
    assert (c.received, c.accepted) == (6, 2)
    assert_all_counted(c)


def test_pose_clock_jumping_back_resets_the_buffer() -> None:
    c, _ = make_collector(pose_window_s=2.0)
    feed_poses(c, resting_poses(10.0, 12.0))
    feed_poses(c, resting_poses(0.0, 0.2))
    assert list(c.pose_rejected.counts().values()) == [1]
    assert "jumped back" in next(iter(c.pose_rejected.counts()))
    assert len(c.poses) == 26
    c.add_profile(profile(0.1), now_s=0.0)
    assert c.paired == 1


def test_moving_robot_and_missing_poses_are_rejected_with_reasons() -> None:
    c, _ = make_collector()
    moving = [
        FlangePose(ns(k / 125), transform_from_rotvec_translation([0, 0, 0], [0.1 * k / 125, 0, 0]))
        for k in range(126)
    ]
    feed_poses(c, moving)
    c.add_profile(profile(0.5), now_s=0.0)  # moving at 100 mm/s
    feed_poses(c, resting_poses(5.0, 6.0))
    c.add_profile(profile(3.0), now_s=0.0)  # no pose within 20 ms
    stages = sorted(k.split(":")[1].strip().split(" ")[0] for k in c.rejected.counts())
    assert stages == ["no", "robot"]
    assert c.paired == 0
    assert_all_counted(c)


@pytest.mark.parametrize("mode", list(Mode))
def test_every_profile_is_counted_once_in_a_random_stream(mode: Mode) -> None:
    rng = np.random.default_rng(7)
    c, _ = make_collector(mode=mode, validation_queue_size=3, max_rate_hz=20.0)
    now = 0.0
    t = 0.0
    for _ in range(400):
        t += float(rng.uniform(0.001, 0.03))
        now += 0.01
        kind = rng.integers(0, 10)
        if kind < 6:
            c.add_pose(FlangePose(ns(t), T_REST), now)
        elif kind < 8:
            c.add_profile(profile(t - float(rng.uniform(-0.01, 0.1))), now)
        elif kind < 9:
            c.reject_profile("garbage")
        elif rng.random() < 0.5:
            drain(c, admit=bool(rng.random() < 0.5))
        else:
            c.arm_capture()
        assert_all_counted(c)
    c.release(now + 10.0)
    drain(c)
    assert c.pending == 0
    assert_all_counted(c)
    assert c.accepted > 0 and c.rejected.total > 0 and c.skipped.total > 0


def test_on_demand_takes_only_the_next_valid_sample_after_a_capture() -> None:
    c, _ = make_collector(mode=Mode.ON_DEMAND)
    feed_poses(c, resting_poses(0.0, 1.9))
    c.add_profile(profile(0.5), now_s=0.0)
    assert c.skipped.counts() == {f"skipped: {SKIP_NOT_CAPTURED}": 1}
    c.arm_capture()
    c.add_profile(profile(1.0), now_s=0.0)
    c.add_profile(profile(1.5), now_s=0.0)
    first, second = c.next_to_validate(), c.next_to_validate()
    assert first is not None and second is not None
    c.reject_validated(Rejection(1, first.sample.stamp_ns, "ellipse", "arc too short"))
    assert c.capture_pending
    assert c.admit(second)
    assert not c.capture_pending and c.captured == second.sample.index
    c.add_profile(profile(1.8), now_s=0.0)
    assert drain(c) == [second.sample.index]
    assert (c.accepted, c.skipped.total) == (1, 2)
    assert_all_counted(c)


def test_max_rate_decimates_on_purpose_and_a_full_validation_queue_skips() -> None:
    c, logged = make_collector(max_rate_hz=10.0)
    feed_poses(c, resting_poses(0.0, 1.5))
    for k in range(30):
        c.add_profile(profile(0.5 + k * 0.02), now_s=0.0)  # 50 Hz
    assert c.skipped.counts() == {f"skipped: {SKIP_RATE}": 24}  # 4 of every 5
    assert drain(c) == [0, 5, 10, 15, 20, 25]
    assert logged.calls == [(f"skipped: {SKIP_RATE}", f"skipped: {SKIP_RATE}")]
    assert_all_counted(c)

    c, _ = make_collector(mode=Mode.ON_DEMAND, validation_queue_size=2)
    feed_poses(c, resting_poses(0.0, 1.5))
    c.arm_capture()
    for k in range(5):
        c.add_profile(profile(0.5 + k * 0.02), now_s=0.0)
    assert c.skipped.counts() == {f"skipped: {SKIP_BACKLOG}": 3}
    assert drain(c) == [0]
    assert_all_counted(c)


def test_clear_keeps_earlier_profiles_out_of_the_new_session() -> None:
    c, _ = make_collector()
    feed_poses(c, resting_poses(0.0, 1.0))
    c.add_profile(profile(0.5), now_s=0.0)  # accepted, not yet stored
    c.add_profile(profile(0.995), now_s=0.0)  # waiting for poses
    c.clear(reloaded=3)
    feed_poses(c, resting_poses(1.008, 1.1))
    assert drain(c) == []
    assert c.skipped.counts() == {f"skipped: {SKIP_CLEARED}": 2}
    assert c.session_samples == 3
    c.add_profile(profile(1.05), now_s=0.0)
    assert drain(c) == [2]
    assert c.session_samples == 4
    assert_all_counted(c)


def test_first_profile_lost_before_matching_is_counted_from_sequence_numbers() -> None:
    # A publisher starts as soon as it sees the subscription; a best-effort subscription that
    # has not matched it yet drops the first messages. They never reach the collector, but
    # the sequence numbers of the ones that do tell how many were lost.
    c, _ = make_collector()
    feed_poses(c, resting_poses(0.0, 1.0))
    c.add_profile(profile(0.2), now_s=0.0, sequence=2)
    c.add_profile(profile(0.3), now_s=0.0, sequence=3)
    c.add_profile(profile(0.6), now_s=0.0, sequence=6)
    values = c.diagnostic_values()
    assert values[KEY_PROFILES_BEFORE] == "1"
    assert values[KEY_PROFILES_LOST] == "2"
    published = 6
    accounted = c.accepted + c.rejected.total + c.skipped.total + c.pending
    assert accounted + int(values[KEY_PROFILES_BEFORE]) + int(values[KEY_PROFILES_LOST]) == (
        published
    )


def stop_and_go_poses(rng: np.random.Generator) -> tuple[list[FlangePose], list[tuple[int, int]]]:
    """Five stops of 1.2 s joined by 0.5 s moves (0.1 m/s, 0.3 rad/s), at 250 Hz with
    10 µm noise; and each stop's [start, end] stamps."""
    poses, stops, t = [], [], 0.0
    position, angle = np.zeros(3), 0.0
    for _ in range(5):
        stops.append((ns(t), ns(t + 1.2)))
        for k in range(300):
            noisy = position + rng.normal(0.0, 10e-6, 3)
            poses.append(
                FlangePose(ns(t + k / 250), transform_from_rotvec_translation([0, 0, angle], noisy))
            )
        t += 1.2
        for k in range(125):
            position = position + np.array([0.1, 0.0, 0.0]) / 250
            angle += 0.3 / 250
            poses.append(
                FlangePose(
                    ns(t + k / 250), transform_from_rotvec_translation([0, 0, angle], position)
                )
            )
        t += 0.5
    return poses, stops


def test_nothing_accepted_says_how_many_and_why_with_the_mode_to_use() -> None:
    """Poses published only around each shot (+-15 ms, the flange elsewhere between shots):
    stop_and_go cannot confirm a standstill, and the collector says so with the fix."""
    c, _ = make_collector(mode=Mode.STOP_AND_GO)
    assert c.nothing_accepted() is None
    for k in range(10):
        T = transform_from_rotvec_translation([0.1, -0.2, 0.3], [0.4 + 0.05 * k, 0.1, 0.5])
        c.add_pose(FlangePose(ns(k - 0.015), T), now_s=0.0)
        c.add_profile(profile(float(k)), now_s=0.0)
        c.add_pose(FlangePose(ns(k + 0.015), T), now_s=0.0)
    c.release(now_s=100.0)
    assert drain(c) == []
    assert_all_counted(c)
    text = c.nothing_accepted()
    assert text is not None
    assert text.startswith("received 10 profiles and set every one aside (10 x skipped: robot")
    assert "standstill_s (0.1 s)" in text
    assert "mode:=on_demand" in text and "mode:=continuous" in text
    c.add_profile(profile(20.5), now_s=0.0)
    feed_poses(c, resting_poses(20.0, 21.0))
    c.release(now_s=200.0)
    assert drain(c) == [10]
    assert c.nothing_accepted() is None


def test_stop_and_go_takes_one_valid_sample_per_standstill_and_counts_the_moving_ones() -> None:
    poses, stops = stop_and_go_poses(np.random.default_rng(3))
    c, logged = make_collector(mode=Mode.STOP_AND_GO, standstill_s=0.3)
    profiles = [profile(k / 100) for k in range(850)]  # 100 Hz for 8.5 s
    events = sorted([(p.stamp_ns, 0, p) for p in poses] + [(q.stamp_ns, 1, q) for q in profiles])
    stored = []
    first_candidate_fails = True
    for k, (_, kind, item) in enumerate(events):
        if kind == 0:
            c.add_pose(item, now_s=0.0)
        else:
            c.add_profile(item, now_s=0.0)
        if k % 10:
            continue  # validation is slower than the profile rate
        pending = c.next_to_validate()
        if pending is not None and first_candidate_fails:  # the stop's first profile is bad
            c.reject_validated(Rejection(pending.sample.index, pending.sample.stamp_ns, "e", "x"))
            first_candidate_fails = False
        elif pending is not None:
            c.admit(pending)
        stored += c.take_to_store()
    c.release(now_s=100.0)
    stored += c.take_to_store()
    # One sample in each of the five stops, taken once the flange has been still for 0.3 s.
    horizon = 0.02 * NS_PER_S
    assert len(stored) == len(stops)
    for sample, (start, end) in zip(stored, stops, strict=True):
        assert start + 0.3 * NS_PER_S <= sample.sample.stamp_ns <= end - horizon
    assert stored[0].sample.stamp_ns > stops[0][0] + 0.3 * NS_PER_S + 0.005 * NS_PER_S
    counts = c.skipped.counts()
    moving = sum(
        1 for p in profiles if not any(a + 0.3e9 <= p.stamp_ns <= b - horizon for a, b in stops)
    )
    # Profiles of the moves and of each stop's first 0.3 s (and its last 20 ms) are left
    # because the flange moved; a few more at each stop's start, where the 20 ms speed
    # window still reaches into the move.
    assert 0 <= counts[f"skipped: {SKIP_MOVING}"] - moving <= 3 * len(stops)
    assert counts[f"skipped: {SKIP_SAMPLED}"] > 0
    assert f"skipped: {SKIP_CANDIDATE}" not in counts  # the queue (20) holds a stop's profiles
    assert any(key == f"skipped: {SKIP_MOVING}" for key, _ in logged.calls)
    assert (c.accepted, c.rejected.total) == (5, 1)
    assert_all_counted(c)


def test_live_clock_offset_on_a_continuous_scan() -> None:
    scenario = scenario_from_preset("continuous", n_poses=20)
    data = simulate(scenario, seed=1)
    truth = -scenario.latency_s  # profiles stamped late: the offset added to their stamps
    tracker = ClockOffsetTracker(PipelineConfig(), period_s=6.0)
    waiting: list[Profile] = []  # a sample reaches the tracker once paired and stored
    for pose in data.poses:
        tracker.add_pose(pose)
        while data.profiles and data.profiles[0].stamp_ns <= pose.stamp_ns:
            waiting.append(data.profiles.pop(0))
        while waiting and waiting[0].stamp_ns < pose.stamp_ns - 0.3 * NS_PER_S:
            tracker.add_sample(waiting.pop(0))
        batch = tracker.take_batch()
        if batch is not None:
            assert tracker.add_estimate(tracker.estimate_batch(*batch)) is None  # no drift
    estimate = tracker.estimate
    assert estimate is not None and estimate.batches >= 2 and estimate.sigma_s is not None
    assert abs(estimate.offset_s - truth) < max(3 * estimate.sigma_s, 0.5e-3)
    assert tracker.add_estimate(truth + 0.02) is not None  # a 20 ms jump is a drift


def test_collector_config_rejects_a_pose_window_shorter_than_the_pairing_horizon() -> None:
    with pytest.raises(ValueError, match="pose_window_s"):
        CollectorConfig(pairing=PairingConfig(sync_tolerance_s=0.5), pose_window_s=0.2)


# -- validation of each sample (what the collector accepts) --------------------------------------


def simulated_samples(profiles: list[Profile], T_base_flange: np.ndarray) -> list[Sample]:
    """Each simulated profile paired with its recorded flange pose."""
    return [
        Sample(k, p.stamp_ns, T, p.points)
        for k, (p, T) in enumerate(zip(profiles, T_base_flange, strict=True))
    ]


def validation_stages(samples: list[Sample], config: PipelineConfig) -> list[str | None]:
    """The rejection stage of each sample (None: valid)."""
    outcomes = [validate_sample(s, config) for s in samples]
    return [None if r is None else r.stage for r in outcomes]


def test_validate_sample_accepts_cylinder_arcs_and_checks_the_radius() -> None:
    data = simulate(scenario_from_preset("ur_scancontrol", n_poses=6), seed=4)
    samples = simulated_samples(data.profiles, data.truth.T_base_flange_recorded)
    radius = data.truth.cylinder.radius
    assert validation_stages(samples, PipelineConfig()) == [None] * 6
    assert (
        validation_stages(samples, PipelineConfig(target_config=CylinderConfig(radius_m=radius)))
        == [None] * 6
    )
    assert (
        validation_stages(
            samples, PipelineConfig(target_config=CylinderConfig(radius_m=2 * radius))
        )
        == ["ellipse"] * 6
    )


def test_validate_sample_finds_the_weld_corner_and_rejects_profiles_without_one() -> None:
    data = simulate_weld(weld_scenario_from_preset("weld_seam_general", n_poses=6), seed=4)
    truth = data.truth
    samples = simulated_samples(data.profiles, truth.T_base_flange_recorded)
    known_point = PipelineConfig(target="known_point")
    assert validation_stages(samples, known_point) == [None] * 6
    for sample, corner in zip(samples, truth.corner_true_sensor, strict=True):
        found = extract_corner(sample, KnownPointConfig(), np.random.default_rng(0))
        assert not isinstance(found, Rejection)
        np.testing.assert_allclose(found.corner_xz, corner[[0, 2]], atol=20e-6)
    # One flank only: the other flank's points (by the simulator's labels) made invalid.
    one_flank = [
        Sample(s.index, s.stamp_ns, s.T_base_flange, np.where(f[:, None] == 1, s.points, np.nan))
        for s, f in zip(samples, truth.flank, strict=True)
    ]
    assert validation_stages(one_flank, known_point) == ["corner"] * 6
    nan_only = Sample(0, 0, T_REST, np.full((640, 3), np.nan))
    assert validation_stages([nan_only], known_point) == ["cleaning"]
    assert validation_stages(samples, PipelineConfig()) == ["ellipse"] * 6  # no cylinder


# -- sample store and summary -----------------------------------------------------------------


def test_store_joins_halves_by_exact_stamp_in_either_order() -> None:
    store = SampleStore(10)
    points = np.ones((3, 3))
    assert store.add_profile(ns(1.0), points, "laser") is None
    store.add_pose(ns(2.0), T_REST, "base_link")
    assert len(store) == 0
    store.add_pose(ns(1.0), T_REST, "base_link")
    store.add_profile(ns(2.0), 2 * points, "laser")
    store.add_profile(ns(1.0), points, "laser")  # replayed by transient_local
    store.add_profile(ns(3.0), points, "laser")  # unmatched
    samples = store.samples()
    assert [(s.index, s.stamp_ns) for s in samples] == [(0, ns(1.0)), (1, ns(2.0))]
    np.testing.assert_array_equal(samples[1].points, 2 * points)
    np.testing.assert_array_equal(samples[0].T_base_flange, T_REST)
    assert store.repeated == 1


def test_store_is_bounded_and_warns_once() -> None:
    store = SampleStore(3)
    warnings = []
    for k in range(6):
        store.add_pose(ns(k), T_REST, "base_link")
        warnings.append(store.add_profile(ns(k), np.zeros((2, 3)), "laser"))
    assert len(store) == 3
    assert [w is not None for w in warnings] == [False, False, False, True, False, False]
    assert "max_samples (3)" in str(warnings[3])
    assert store.ignored_full == 3
    for k in range(10, 15):
        store.add_profile(ns(k), np.zeros((2, 3)), "laser")
    assert store.dropped_unmatched == 2


def test_store_drops_samples_when_the_collector_session_changes() -> None:
    store = SampleStore(10)
    store.add_pose(ns(1.0), T_REST, "base_link")
    store.add_profile(ns(1.0), np.zeros((2, 3)), "laser")
    assert store.set_session("/s/session_1") == 0
    assert store.set_session("/s/session_1") == 0
    assert len(store) == 1
    assert store.set_session("/s/session_2") == 1
    assert len(store) == 0


def known_result() -> CalibrationResult:
    R = Rotation.from_euler("xyz", [10.0, -5.0, 95.0], degrees=True).as_matrix()
    return CalibrationResult(
        T_flange_sensor=transform_from_rotation_translation(R, [0.012, -0.085, 0.095]),
        target=CylinderSection(
            Cylinder(np.array([0.45, 0.15, 0.0]), np.array([0.0, 0.0, 1.0]), 0.02)
        ),
        method="default",
        samples_used=list(range(28)),
        samples_rejected=[],
        rms_residual_m=6.5e-6,
        uncertainty_translation_m=np.array([1e-5, 2e-5, 0.5e-5]),
        uncertainty_rotation_rad=np.radians([0.001, 0.003, 0.002]),
    )


def test_summary_line_gives_every_number_with_its_unit() -> None:
    text = one_line_summary(known_result(), 30)
    assert "\n" not in text
    # The verdict first, as everywhere (issue 30): no self-check, so not good, and why.
    assert text.startswith("Verdict: USE WITH CARE (accuracy in use not measured): not checked")
    assert "tool0 -> laser" in text
    assert "translation [12.000, -85.000, 95.000] mm" in text
    assert "rpy [10.0000, -5.0000, 95.0000] deg" in text
    assert "1-sigma (largest axis) 0.0200 mm, 0.0030 deg" in text
    assert "28 of 30 samples used" in text
    assert "rms residual 6.5 um" in text


def test_marker_points_lie_on_the_cylinder_and_respect_the_budget() -> None:
    rng = np.random.default_rng(3)
    result = known_result()
    assert isinstance(result.target, CylinderSection)
    cylinder = result.target.cylinder
    for k in range(4):
        T_base_flange = transform_from_rotvec_translation(
            rng.normal(0, 0.5, 3), rng.normal([0.4, 0.1, 0.3], 0.05)
        )
        angle = rng.uniform(0, 2 * np.pi, 400)
        height = rng.uniform(0.02, 0.08, 400)
        surface = np.column_stack(
            [0.45 + 0.02 * np.cos(angle), 0.15 + 0.02 * np.sin(angle), height]
        )
        T_sensor_base = invert_transform(T_base_flange @ result.T_flange_sensor)
        points = apply_transform(T_sensor_base, surface)
        result.sample_fits.append(SampleFit(k, ns(k), T_base_flange, points, np.zeros(2)))
    points = points_in_base(result, max_points=500)
    assert 400 <= len(points) <= 500
    distance = np.linalg.norm(points[:, :2] - [0.45, 0.15], axis=1)
    np.testing.assert_allclose(distance, cylinder.radius, atol=1e-9)
    centre, length = axis_extent(points, cylinder)
    assert centre[2] == pytest.approx(0.05, abs=0.003)
    assert length == pytest.approx(1.1 * 0.06, abs=0.005)


# -- the service's pipeline configuration ---------------------------------------------------------


def service_values(**overrides: Any) -> dict[str, Any]:
    """calibration_service parameter values: the declared defaults with ``overrides``."""
    values = {spec.name: spec.default for spec in calibration_service.PARAMETERS}
    assert set(overrides) <= set(values), set(overrides) - set(values)
    return {**values, **overrides}


def test_service_puts_the_live_clock_offset_in_the_result_and_warns_on_a_mismatch() -> None:
    def result() -> CalibrationResult:
        return CalibrationResult(np.eye(4), None, "default", [0], [], 1e-5)

    agreeing = result()
    calibration_service.add_live_clock_offset(agreeing, -0.004, -0.0041, 0.0002)
    assert agreeing.clock_offset_s == -0.004
    assert (agreeing.clock_offset_live_s, agreeing.clock_offset_live_sigma_s) == (-0.0041, 0.0002)
    assert agreeing.warnings == []
    mismatched = result()
    calibration_service.add_live_clock_offset(mismatched, 0.0, -0.004, 0.0002)
    (warning,) = mismatched.warnings
    assert "-4.00 +- 0.20 ms" in warning and "clock_offset_s to -0.0040" in warning
    no_sigma_yet = result()
    calibration_service.add_live_clock_offset(no_sigma_yet, 0.0, -0.004, float("nan"))
    assert no_sigma_yet.clock_offset_live_sigma_s is None and no_sigma_yet.warnings == []
    none = result()
    calibration_service.add_live_clock_offset(none, 0.002, float("nan"), float("nan"))
    assert (none.clock_offset_s, none.clock_offset_live_s) == (0.002, None)


def test_service_builds_the_known_point_configuration_from_its_parameters() -> None:
    initial = read_result_yaml(WELD_INITIAL)
    assert isinstance(initial.target, KnownPoint)
    default = calibration_service.pipeline_config(service_values())
    assert (default.target, default.method) == ("cylinder", Method.DEFAULT)
    assert isinstance(default.target_config, CylinderConfig)
    assert default.initial_T_flange_sensor is None
    config = calibration_service.pipeline_config(
        service_values(
            target="known_point",
            method="paper",
            known_point=tuple(initial.target.point),
            initial_hand_eye_path=str(WELD_INITIAL),
        )
    )
    assert (config.target, config.method) == ("known_point", Method.PAPER)
    point = config.target_config.point_m
    assert point is not None and config.initial_T_flange_sensor is not None
    np.testing.assert_array_equal(point, initial.target.point)
    assert_floats_close(config.initial_T_flange_sensor, initial.T_flange_sensor)


def test_service_takes_the_initial_hand_eye_as_numbers_and_logs_normalisation() -> None:
    warnings: list[str] = []
    config = calibration_service.pipeline_config(
        service_values(initial_hand_eye_path="0.1 0.2 0.3 0 0 0.7071 0.7071"), warnings.append
    )
    assert config.initial_T_flange_sensor is not None
    assert_floats_close(config.initial_T_flange_sensor[:3, 3], [0.1, 0.2, 0.3])
    assert len(warnings) == 1 and warnings[0].startswith("initial_hand_eye_path: the quaternion")
    with pytest.raises(InputError, match=r"initial_hand_eye_path: .*millimetres"):
        calibration_service.pipeline_config(
            service_values(initial_hand_eye_path="100 200 300 0 0 0 1")
        )


def test_service_configuration_errors_name_the_parameters(tmp_path: Path) -> None:
    with pytest.raises(ResultFileError, match=r"cannot use initial_hand_eye_path: .*missing\.yaml"):
        calibration_service.pipeline_config(
            service_values(initial_hand_eye_path=str(tmp_path / "missing.yaml"))
        )
    garbage = tmp_path / "garbage.yaml"
    garbage.write_text("hand_eye: {translation: [1, 2]}\n", encoding="utf-8")
    with pytest.raises(ResultFileError, match=r"initial_hand_eye_path: .*garbage\.yaml"):
        calibration_service.pipeline_config(service_values(initial_hand_eye_path=str(garbage)))
    given = {"known_point": (0.55, 0.1, 0.02), "initial_hand_eye_path": str(WELD_INITIAL)}
    for missing in ({"known_point": ()}, {"initial_hand_eye_path": ""}):
        with pytest.raises(InputError, match=r"set known_point to .* and initial_hand_eye_path"):
            calibration_service.pipeline_config(
                service_values(target="known_point", method="paper", **{**given, **missing})
            )


# -- launch file ----------------------------------------------------------------------------------


def test_launch_file_imports_without_the_launch_packages() -> None:
    if importlib.util.find_spec("launch_ros") is not None:
        pytest.skip("launch_ros is installed: `ros2 launch` exercises the launch file")
    spec = importlib.util.spec_from_file_location(
        "linelaser_calib_launch", REPO_ROOT / "launch" / "linelaser_calib.launch.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    with pytest.raises(RuntimeError, match="ros2 run linelaser_calib collector"):
        module.generate_launch_description()


# -- in-process nodes (rclpy, private DDS domain) ------------------------------------------------


@pytest.fixture
def ros_context() -> Iterator[tuple[Context, int]]:
    domain = new_domain_id()
    context = init_context(domain)
    try:
        yield context, domain
    finally:
        context.try_shutdown()


NODES = {
    "collector": (collector.CollectorNode, collector.PARAMETERS),
    "calibration_service": (
        calibration_service.CalibrationServiceNode,
        calibration_service.PARAMETERS,
    ),
}


@pytest.mark.ros
@pytest.mark.parametrize("name", sorted(NODES))
def test_parameter_file_matches_the_declarations(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("HOME", str(tmp_path))  # the collector's default session_dir is ~/...
    path = REPO_ROOT / "config" / f"{name}.yaml"
    in_file = yaml.safe_load(path.read_text(encoding="utf-8"))["/**"]["ros__parameters"]
    node_class, specs = NODES[name]
    assert sorted(in_file) == sorted(spec.name for spec in specs)
    for spec in specs:
        value = tuple(in_file[spec.name]) if spec.is_array else in_file[spec.name]
        assert type(value) is type(spec.default) and value == spec.default, spec.name
        descriptor = spec.descriptor()
        assert descriptor.description, spec.name
        if spec.bounds is not None:
            ranges = descriptor.floating_point_range or descriptor.integer_range
            assert ranges[0].from_value <= spec.default <= ranges[0].to_value, spec.name
    # The file as rcl parses it (--params-file): every value accepted with its declared type.
    context = init_context(new_domain_id(), ["--ros-args", "--params-file", str(path)])
    try:
        node = node_class(context=context)
        try:
            undeclared = set(node._parameters) - set(in_file)
            assert undeclared == {"use_sim_time", "start_type_description_service"}
            assert parameter_values(node, specs) == {
                spec.name: spec.value(in_file[spec.name]) for spec in specs
            }
        finally:
            node.destroy_node()
    finally:
        context.try_shutdown()


@pytest.mark.ros
def test_collector_refuses_an_unknown_mode(
    ros_context: tuple[Context, int], tmp_path: Path
) -> None:
    context, _ = ros_context
    with pytest.raises(CalibrationError, match="mode is 'sideways'; it must be one of"):
        collector.CollectorNode(
            context=context,
            parameter_overrides=[
                Parameter("mode", value="sideways"),
                Parameter("session_dir", value=str(tmp_path)),
            ],
        )


@pytest.mark.ros
def test_known_point_parameter_takes_an_empty_array_or_three_numbers(
    ros_context: tuple[Context, int],
) -> None:
    context, _ = ros_context
    with pytest.raises(
        CalibrationError,
        match=r"known_point is \[0\.5, 0\.1\]; it must be \[\] or an array of 3 finite",
    ):
        calibration_service.CalibrationServiceNode(
            context=context, parameter_overrides=[Parameter("known_point", value=[0.5, 0.1])]
        )
    node = calibration_service.CalibrationServiceNode(context=context)
    try:
        for value, accepted in (
            ([0.55, 0.1, 0.02], True),
            ([1, 0, 0], True),
            ([0.5, 0.1], False),
            ([0.5, float("nan"), 0.1], False),
            ("0.5, 0.1, 0.0", False),
            ([], True),
        ):
            (outcome,) = node.set_parameters([Parameter("known_point", value=value)])
            assert outcome.successful is accepted, (value, outcome.reason)
            if accepted:
                expected = tuple(float(v) for v in value)
                assert parameter_values(node, calibration_service.PARAMETERS)["known_point"] == (
                    expected
                )
    finally:
        node.destroy_node()


@pytest.fixture(scope="module")
def real_samples() -> list[tuple[Profile, FlangePose]]:
    """Three simulated samples (profile and flange pose at its stamp)."""
    data = simulate(scenario_from_preset("ur_scancontrol", n_poses=3), seed=5)
    return [
        (p, FlangePose(p.stamp_ns, T, "base_link"))
        for p, T in zip(data.profiles, data.truth.T_base_flange_recorded, strict=True)
    ]


@pytest.fixture
def service(ros_context: tuple[Context, int], tmp_path: Path) -> Iterator[ServiceUnderTest]:
    context, domain = ros_context
    under_test = ServiceUnderTest(context, domain, tmp_path / "hand_eye.yaml")
    try:
        yield under_test
    finally:
        under_test.close()


@pytest.mark.ros
def test_calibrate_without_samples_says_so(service: ServiceUnderTest) -> None:
    answer = service.probe.call("calibrate")
    assert not answer.success
    assert "no samples yet" in answer.message


@pytest.mark.ros
def test_calibrate_with_too_few_samples_gives_the_pipeline_reason(
    service: ServiceUnderTest, real_samples: list[tuple[Profile, FlangePose]]
) -> None:
    service.send(real_samples)
    answer = service.probe.call("calibrate")
    assert not answer.success
    assert "at least 8" in answer.message
    assert not (Path(service.node.get_parameter("output_path").value)).exists()


@pytest.mark.ros
def test_calibrate_with_an_unreadable_initial_hand_eye_says_why(
    service: ServiceUnderTest, real_samples: list[tuple[Profile, FlangePose]], tmp_path: Path
) -> None:
    service.send(real_samples)
    missing = tmp_path / "old_hand_eye.yaml"
    service.node.set_parameters([Parameter("initial_hand_eye_path", value=str(missing))])
    answer = service.probe.call("calibrate")
    assert not answer.success
    assert answer.message.startswith("cannot use initial_hand_eye_path: ")
    assert str(missing) in answer.message


@pytest.mark.ros
def test_a_second_call_during_a_solve_is_refused_and_failures_keep_the_last_file(
    service: ServiceUnderTest,
    real_samples: list[tuple[Profile, FlangePose]],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    truth = known_result()
    release = threading.Event()
    behaviour: dict[str, Any] = {"raise": None}

    def fake_calibrate(samples: list[Any], *_: Any) -> CalibrationResult:
        assert len(samples) == len(real_samples)
        if behaviour["raise"] is not None:
            raise behaviour["raise"]
        release.wait(20.0)
        truth.samples_used = [s.index for s in samples]
        return truth

    monkeypatch.setattr(calibration_service, "calibrate_live", fake_calibrate)
    service.send(real_samples)
    first = service.probe.call_async("calibrate")
    time.sleep(0.3)
    second = service.probe.call("calibrate", timeout_s=5.0)
    assert not second.success and "already running" in second.message
    assert not first.done()
    release.set()
    wait_for(first.done, 20.0, "the first calibration")
    answer = first.result()
    assert answer.success, answer.message
    assert "3 of 3 samples used" in answer.message
    output = Path(service.node.get_parameter("output_path").value)
    written = read_result_yaml(output)
    assert max(transform_error(written.T_flange_sensor, truth.T_flange_sensor)) < 1e-9
    assert max(transform_error(service.probe.hand_eye(), truth.T_flange_sensor)) < 1e-6
    before = output.read_bytes()

    behaviour["raise"] = DegenerateError("the poses only translate: rotate the sensor")
    answer = service.probe.call("calibrate")
    assert (answer.success, answer.message) == (
        False,
        "the poses only translate: rotate the sensor",
    )
    behaviour["raise"] = ZeroDivisionError("a bug")
    answer = service.probe.call("calibrate")
    assert not answer.success and "internal error" in answer.message
    assert output.read_bytes() == before
    assert not service.probe.call("calibrate").success  # still answering


@pytest.mark.ros
def test_collector_reloads_the_latest_session_into_a_new_one_and_republishes_it(
    ros_context: tuple[Context, int],
    tmp_path: Path,
    real_samples: list[tuple[Profile, FlangePose]],
) -> None:
    context, domain = ros_context
    root = tmp_path / "sessions"
    with SessionBagWriter(root / "session_20200101_000000") as old:
        for p, pose in real_samples[:2]:
            old.append(p, pose)
    with SessionBagWriter(root / "session_20250101_000000") as latest:
        for p, pose in real_samples:
            latest.append(p, pose)
    node = collector.CollectorNode(
        context=context,
        parameter_overrides=[
            Parameter("session_dir", value=str(root)),
            Parameter("reload_session", value="latest"),
        ],
    )
    probe = RosProbe(domain)
    try:
        received: list[int] = []
        probe.node.create_subscription(
            PoseStamped,
            "linelaser_calib/samples/flange_pose",
            lambda msg: received.append(msg.header.stamp.sec * NS_PER_S + msg.header.stamp.nanosec),
            reliable_qos(100, latched=True),
        )
        stamps = [p.stamp_ns for p, _ in real_samples]
        wait_for(lambda: sorted(received) == stamps, 20.0, "the republished samples")
        (new,) = set(root.glob("session_*")) - {old.path, latest.path}
        assert [p.stamp_ns for p in read_bag(new).profiles] == stamps
        assert len(read_bag(latest.path).profiles) == len(stamps)  # the source is untouched
    finally:
        probe.close()
        node.destroy_node()


def test_reference_doc_parameter_tables_match_the_declarations() -> None:
    from linelaser_calib.nodes import calibration_service, collector
    from linelaser_calib.nodes.common import markdown_parameter_table

    reference = (Path(__file__).resolve().parent.parent / "docs" / "reference.md").read_text()
    for module in (collector, calibration_service):
        table = markdown_parameter_table(module.PARAMETERS)
        assert table in reference, (
            f"docs/reference.md parameter table of {module.__name__} is out of date"
        )


def test_service_sets_the_along_line_scale_as_the_command_line_does() -> None:
    default = calibration_service.pipeline_config(service_values())
    assert default.target_config.scale == "auto"
    for mode in ("auto", "fixed", "free"):
        config = calibration_service.pipeline_config(service_values(scale=mode, radius=0.02))
        assert config.target_config.scale == mode
    for refused in (
        service_values(scale="free", method="paper"),
        service_values(scale="free", target="known_point"),
    ):
        with pytest.raises(CalibrationError, match="scale does not"):
            calibration_service.pipeline_config(refused)
