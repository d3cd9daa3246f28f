"""The nodes' TF pieces: the live pose source tf, and the check for a second parent."""

from __future__ import annotations

from pathlib import Path

import pytest
from rclpy.parameter import Parameter
from ros_helpers import init_context, new_domain_id

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.nodes import calibration_service, collector, tf_input

#: The parents that robot_state_publisher's /tf_static gives when a URDF already places the laser.
PARENTS = {"tool0": "flange", "laser": "wrist_3_link"}


def test_a_sensor_frame_with_another_parent_is_reported() -> None:
    warning = calibration_service.second_parent_warning(PARENTS, "laser", "tool0")
    assert warning is not None
    assert "laser already has parent wrist_3_link" in warning and "two parents" in warning
    assert "--format urdf" in warning
    assert calibration_service.second_parent_warning(PARENTS, "laser", "wrist_3_link") is None
    assert calibration_service.second_parent_warning(PARENTS, "scanner", "tool0") is None
    assert calibration_service.second_parent_warning({}, "laser", "tool0") is None


@pytest.mark.ros
def test_collector_pose_source_tf_says_what_it_needs_without_tf2_msgs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(tf_input, "_MISSING", ImportError("No module named 'tf2_msgs'"))
    context = init_context(new_domain_id())
    try:
        with pytest.raises(
            CalibrationError, match=r"pose_source 'tf' needs the tf2_msgs.*make venv"
        ):
            collector.CollectorNode(
                context=context,
                parameter_overrides=[
                    Parameter("pose_source", value="tf"),
                    Parameter("session_dir", value=str(tmp_path)),
                ],
            )
    finally:
        context.try_shutdown()
