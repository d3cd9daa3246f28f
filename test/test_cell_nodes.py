"""The nodes' TF pieces: the live pose source tf, and the check for a second parent."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
from rclpy.parameter import Parameter
from ros_helpers import init_context, new_domain_id

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.nodes import calibration_service, collector

#: What tf2_ros.Buffer.all_frames_as_yaml() returns for a URDF that already places the laser.
FRAMES_YAML = """\
tool0:
  parent: 'flange'
  broadcaster: 'default_authority'
  rate: 10000.000
  most_recent_transform: 0.000000
  oldest_transform: 0.000000
  buffer_length: 0.000
laser:
  parent: 'wrist_3_link'
  broadcaster: 'default_authority'
  rate: 10000.000
  most_recent_transform: 0.000000
  oldest_transform: 0.000000
  buffer_length: 0.000
"""


def test_a_sensor_frame_with_another_parent_is_reported() -> None:
    warning = calibration_service.second_parent_warning(FRAMES_YAML, "laser", "tool0")
    assert warning is not None
    assert "laser already has parent wrist_3_link" in warning and "two parents" in warning
    assert "--format urdf" in warning
    assert calibration_service.second_parent_warning(FRAMES_YAML, "laser", "wrist_3_link") is None
    assert calibration_service.second_parent_warning(FRAMES_YAML, "scanner", "tool0") is None
    assert calibration_service.second_parent_warning("", "laser", "tool0") is None


@pytest.mark.ros
def test_collector_pose_source_tf_says_what_it_needs_without_tf2_msgs(tmp_path: Path) -> None:
    if importlib.util.find_spec("tf2_msgs") is not None:
        pytest.skip("tf2_msgs is installed: the live TF source can start")
    context = init_context(new_domain_id())
    try:
        with pytest.raises(CalibrationError, match="pose_source 'tf' needs the tf2_msgs"):
            collector.CollectorNode(
                context=context,
                parameter_overrides=[
                    Parameter("pose_source", value="tf"),
                    Parameter("session_dir", value=str(tmp_path)),
                ],
            )
    finally:
        context.try_shutdown()
