"""Over DDS: calibration_service's ~/plan publishes the planned flange poses and their fans."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray
from ros_helpers import Recording, params
from test_ros_e2e import REPLAY_10X, SHORT_SCAN, Graph, graph, settled  # noqa: F401 - graph is a fixture
from visualization_msgs.msg import MarkerArray

from linelaser_calib.core.geometry import transform_from_translation_quaternion
from linelaser_calib.sim import scenario_from_preset, simulate

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_plan_service_publishes_feasible_poses_after_a_calibration(graph: Graph) -> None:  # noqa: F811
    scenario = scenario_from_preset("ur_scancontrol", **SHORT_SCAN)
    data = simulate(scenario, seed=3)
    recording = Recording.from_data(data.profiles, data.poses)
    graph.collector(*params(**REPLAY_10X))
    graph.service(*params(radius=0.02, plan_poses=6, plan_axial_range=[0.0, 0.1]))
    probe = graph.probe
    player = probe.player()
    player.wait_matched()
    sent = player.play(recording, rate=10.0)
    accepted = settled(probe.wait_counts(20.0, profiles_received=sent, profiles_pending=0))
    probe.wait_counts(10.0, node="calibration_service", samples=accepted)
    before = probe.call("/calibration_service/plan")
    assert not before.success and "call calibrate first" in before.message
    assert probe.call("/calibrate").success

    answer = probe.call("/calibration_service/plan")
    assert answer.success, answer.message + graph.procs.logs()
    assert answer.message.startswith("planned 6 flange poses") and "\n" not in answer.message
    planned: PoseArray = probe.latched(PoseArray, "linelaser_calib/planned_poses")
    assert planned.header.frame_id == "base_link" and len(planned.poses) == 6
    T_flange = np.stack(
        [
            transform_from_translation_quaternion(
                [p.position.x, p.position.y, p.position.z],
                [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w],
            )
            for p in planned.poses
        ]
    )
    T_sensor = T_flange @ data.truth.T_flange_sensor
    # Above the table, looking down or level, the sensor in reach of the shaft (true scene).
    assert np.all(T_sensor[:, 2, 3] > 0.0) and np.all(T_sensor[:, 2, 2] <= 0.01)
    axis_xy = np.array(scenario.cylinder_base_m[:2])
    distance = np.linalg.norm(T_sensor[:, :2, 3] - axis_xy, axis=1)
    assert np.all(distance < scenario.z_max_m + scenario.cylinder_radius_m + 0.05)
    fans: MarkerArray = probe.latched(MarkerArray, "linelaser_calib/planned_fans")
    lines = [m for m in fans.markers if m.ns == "planned_fans"]
    assert len(lines) == 1 and len(lines[0].points) == 6 * 8
    # The diagnostics may still show the state before the plan: wait for the plan's count.
    values = probe.wait_counts(10.0, node="calibration_service", samples=accepted, planned_poses=6)
    sigma_mm = [
        float(v) for v in values["predicted 1 sigma translation after the plan (mm)"].split()
    ]
    sigma_deg = [
        float(v) for v in values["predicted 1 sigma rotation after the plan (deg)"].split()
    ]
    assert 0.0 < max(sigma_mm) < 0.5 and 0.0 < max(sigma_deg) < math.degrees(0.002)
