"""Pairing against known interpolated poses, unsorted/duplicate stamps and clock offsets."""

from __future__ import annotations

import numpy as np
import pytest

from linelaser_calib.core.geometry import (
    rotation_angle,
    transform_from_rotvec_translation,
)
from linelaser_calib.core.pairing import NS_PER_S, PairingConfig, PoseBuffer, pair_profiles
from linelaser_calib.core.types import FlangePose, Profile, Sample

T0_NS = 1_700_000_000 * NS_PER_S


def linear_motion(t_s: float, speed: float = 0.01, spin: float = 0.02) -> np.ndarray:
    """Flange moving along x at ``speed`` m/s and turning about z at ``spin`` rad/s."""
    return transform_from_rotvec_translation([0.0, 0.0, spin * t_s], [speed * t_s, 0.2, 0.3])


def pose_stream(rate_hz: float, duration_s: float, **motion: float) -> list[FlangePose]:
    n = int(duration_s * rate_hz) + 1
    return [
        FlangePose(T0_NS + round(k / rate_hz * NS_PER_S), linear_motion(k / rate_hz, **motion))
        for k in range(n)
    ]


def profile_at(t_s: float) -> Profile:
    return Profile(T0_NS + round(t_s * NS_PER_S), np.zeros((3, 3)))


MOVING = PairingConfig(max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)


def test_interpolated_pose_matches_motion() -> None:
    poses = pose_stream(125.0, 2.0)
    times = [0.1013, 0.5, 0.777, 1.9999]
    result = pair_profiles([profile_at(t) for t in times], poses, MOVING)
    assert len(result.samples) == len(times)
    for sample, t in zip(result.samples, times, strict=True):
        truth = linear_motion(t)
        np.testing.assert_allclose(sample.T_base_flange[:3, 3], truth[:3, 3], atol=1e-9)
        assert rotation_angle(sample.T_base_flange[:3, :3].T @ truth[:3, :3]) < 1e-9


def test_unsorted_and_duplicate_poses_are_handled() -> None:
    rng = np.random.default_rng(0)
    poses = pose_stream(125.0, 1.0)
    shuffled = [poses[i] for i in rng.permutation(len(poses))] + poses[:10]
    result = pair_profiles([profile_at(0.5037)], shuffled, MOVING)
    assert len(result.samples) == 1
    np.testing.assert_allclose(
        result.samples[0].T_base_flange[:3, 3], linear_motion(0.5037)[:3, 3], atol=1e-9
    )
    assert any("out of stamp order" in n for n in result.notes)
    assert any("repeated a stamp" in n for n in result.notes)


def test_duplicate_profile_stamp_rejected() -> None:
    result = pair_profiles([profile_at(0.5), profile_at(0.5)], pose_stream(125.0, 1.0), MOVING)
    assert [s.index for s in result.samples] == [0]
    assert result.rejected[0].index == 1 and "duplicate" in result.rejected[0].reason


def test_nearest_pose_used_when_only_one_is_close() -> None:
    poses = [
        FlangePose(T0_NS, linear_motion(0.0)),
        FlangePose(T0_NS + NS_PER_S, linear_motion(1.0)),
    ]
    result = pair_profiles([profile_at(0.01)], poses, MOVING)
    np.testing.assert_allclose(result.samples[0].T_base_flange, linear_motion(0.0))


def test_profile_far_from_any_pose_rejected_with_reason() -> None:
    poses = [
        FlangePose(T0_NS, linear_motion(0.0)),
        FlangePose(T0_NS + NS_PER_S, linear_motion(1.0)),
    ]
    result = pair_profiles([profile_at(0.5)], poses, MOVING)
    assert not result.samples
    assert "no flange pose within 20.0 ms" in result.rejected[0].reason


def test_clock_offset_reported_and_corrected() -> None:
    poses = pose_stream(125.0, 2.0, speed=0.0, spin=0.0)
    offset_s = 5.0
    profiles = [profile_at(t - offset_s) for t in (0.5, 1.0, 1.5)]
    default = PairingConfig()
    result = pair_profiles(profiles, poses, default)
    assert not result.samples
    assert result.median_offset_s == pytest.approx(offset_s - 1.0, abs=0.01)
    assert result.span_offset_s == pytest.approx(offset_s, abs=0.01)
    message = result.explain_nothing_paired(default)
    assert "do not overlap" in message and "clock offset to about 5.000 s" in message
    fixed = pair_profiles(profiles, poses, PairingConfig(clock_offset_s=offset_s))
    assert len(fixed.samples) == 3


def test_moving_robot_flagged() -> None:
    poses = pose_stream(500.0, 2.0, speed=0.05, spin=0.0)
    result = pair_profiles([profile_at(1.0)], poses, PairingConfig())
    assert not result.samples
    assert "robot moving at 50.0 mm/s" in result.rejected[0].reason
    spinning = pair_profiles(
        [profile_at(1.0)], pose_stream(500.0, 2.0, speed=0.0, spin=0.5), PairingConfig()
    )
    assert "rotating" in spinning.rejected[0].reason


def test_step_and_shoot_stationary_profile_accepted() -> None:
    poses = pose_stream(125.0, 2.0, speed=0.0, spin=0.0)
    result = pair_profiles([profile_at(1.0)], poses, PairingConfig())
    assert isinstance(result.samples[0], Sample)


def test_live_buffer_ready_and_bounded() -> None:
    config = PairingConfig()
    buffer = PoseBuffer(max_age_s=0.5)
    stream = pose_stream(125.0, 3.0, speed=0.0, spin=0.0)
    target = T0_NS + NS_PER_S
    ready_at = None
    for pose in stream:
        buffer.add(pose)
        if ready_at is None and buffer.ready_for(target, config):
            ready_at = pose.stamp_ns
    assert ready_at is not None and ready_at >= target + 0.02 * NS_PER_S
    assert len(buffer) <= 0.5 * 125 + 2


def test_pose_track_queries_equal_the_pose_by_pose_interpolation() -> None:
    """PoseTrack.at (all stamps at once, Slerp) against interpolate_transform of the two
    bracketing poses, the nearest pose, or none, at random stamps of an unevenly sampled
    stream with gaps."""
    from linelaser_calib.core.geometry import interpolate_transform
    from linelaser_calib.core.pose_track import PoseTrack

    rng = np.random.default_rng(3)
    stamps = np.cumsum(rng.choice([2, 3, 40], size=300) * 1_000_000) + T0_NS
    poses = [
        FlangePose(
            int(t), transform_from_rotvec_translation(rng.normal(size=3), rng.normal(size=3))
        )
        for t in stamps
    ]
    track, dropped = PoseTrack.from_poses(poses[::-1] + poses[:5]).sorted()
    assert dropped == 5 and track.stamps_ns.tolist() == stamps.tolist()
    tolerance = 20_000_000
    queries = np.concatenate(
        [stamps[:50], rng.integers(stamps[0] - 10**8, stamps[-1] + 10**8, 400)]
    )
    T, found = track.at(queries, tolerance)
    for t, got, ok in zip(queries.tolist(), T, found, strict=True):
        i = int(np.searchsorted(stamps, t))
        before = i > 0 and t - stamps[i - 1] <= tolerance
        after = i < len(stamps) and stamps[i] - t <= tolerance
        if i < len(stamps) and stamps[i] == t:
            expected = poses[i].T_base_flange
        elif before and after:
            s = (t - stamps[i - 1]) / (stamps[i] - stamps[i - 1])
            expected = interpolate_transform(poses[i - 1].T_base_flange, poses[i].T_base_flange, s)
        elif before or after:
            expected = poses[i - 1 if before else i].T_base_flange
        else:
            assert not ok
            continue
        assert ok
        np.testing.assert_allclose(got, expected, atol=1e-12)
