"""A robot_state_publisher-style TF tree for a simulated flange-pose stream.

The recorded flange poses ``T_base_flange`` are split into a UR-like chain whose product
is exactly each pose::

    base_link -s-> base_link_inertia -d-> shoulder_link -d-> forearm_link -d-> wrist_3_link
              -s-> flange -s-> tool0            (s: /tf_static, d: /tf at every pose stamp)
    base_link -s-> base                         (UR's base: base_link turned 180 deg about z)

The static links use the UR description's fixed rotations (base_link_inertia and base are
turned 180 deg about z; wrist_3_link -> flange is rpy (0, -90, -90) deg and flange -> tool0
rpy (90, 0, 90) deg). The dynamic split is arbitrary but smooth: the shoulder turns about z
towards the wrist, and the rest is shared between two links by half of its rotation and
translation.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from linelaser_calib.core.geometry import (
    FloatArray,
    interpolate_transform,
    invert_transform,
    transform_from_rotation_translation,
)
from linelaser_calib.core.tf import StampedTransform
from linelaser_calib.core.types import FlangePose

#: Height of UR5e's shoulder above its base, m.
SHOULDER_HEIGHT_M = 0.1625


def _fixed(rpy_rad: tuple[float, float, float]) -> FloatArray:
    R = Rotation.from_euler("xyz", rpy_rad).as_matrix()
    return transform_from_rotation_translation(R, np.zeros(3))


def ur_tf_tree(
    poses: list[FlangePose], base_frame: str, flange_frame: str
) -> tuple[list[StampedTransform], list[StampedTransform]]:
    """Dynamic (``/tf``) and static (``/tf_static``) transforms whose chain gives ``poses``.

    Parameters
    ----------
    poses : list of FlangePose
        The flange-pose stream, ``T_base_flange`` (4, 4) in m.
    base_frame, flange_frame : str
        Names of the chain's ends (``base_link`` and ``tool0`` for a UR).

    Returns
    -------
    dynamic : list of StampedTransform
        Three per pose, at the pose's stamp.
    static : list of StampedTransform
        The fixed links, stamped with the first pose's stamp.
    """
    half_turn = _fixed((0.0, 0.0, np.pi))
    T_wrist_flange = _fixed((0.0, -np.pi / 2, -np.pi / 2))
    T_flangelink_tool = _fixed((np.pi / 2, 0.0, np.pi / 2))
    T_wrist_tool = T_wrist_flange @ T_flangelink_tool
    stamp0 = poses[0].stamp_ns if poses else 0
    static = [
        StampedTransform(stamp0, base_frame, "base_link_inertia", half_turn),
        StampedTransform(stamp0, "wrist_3_link", "flange", T_wrist_flange),
        StampedTransform(stamp0, "flange", flange_frame, T_flangelink_tool),
    ]
    if base_frame != "base":
        static.append(StampedTransform(stamp0, base_frame, "base", half_turn))
    dynamic = []
    for pose in poses:
        T_inertia_wrist = invert_transform(half_turn) @ pose.T_base_flange
        T_inertia_wrist = T_inertia_wrist @ invert_transform(T_wrist_tool)
        x, y, _ = T_inertia_wrist[:3, 3]
        T_inertia_shoulder = transform_from_rotation_translation(
            Rotation.from_euler("z", np.arctan2(y, x)).as_matrix(), [0.0, 0.0, SHOULDER_HEIGHT_M]
        )
        T_shoulder_wrist = invert_transform(T_inertia_shoulder) @ T_inertia_wrist
        T_shoulder_forearm = interpolate_transform(np.eye(4), T_shoulder_wrist, 0.5)
        T_forearm_wrist = invert_transform(T_shoulder_forearm) @ T_shoulder_wrist
        dynamic += [
            StampedTransform(
                pose.stamp_ns, "base_link_inertia", "shoulder_link", T_inertia_shoulder
            ),
            StampedTransform(pose.stamp_ns, "shoulder_link", "forearm_link", T_shoulder_forearm),
            StampedTransform(pose.stamp_ns, "forearm_link", "wrist_3_link", T_forearm_wrist),
        ]
    return dynamic, static
