"""A URDF of a DH arm, written the way UR's ROS description places its joints."""

from __future__ import annotations

import math

from linelaser_calib.core.robot.kinematics import UR_DH, UR_JOINT_NAMES


def ur_urdf(preset: str = "ur5e", joint_names: tuple[str, ...] = UR_JOINT_NAMES) -> str:
    """URDF text of a UR preset: base_link, base_link_inertia turned 180 deg about z, the six
    joints with origins ``Tx(a[i-1]) Rx(alpha[i-1]) Tz(d[i])`` about z, then tool0."""
    d, a, alpha = UR_DH[preset]
    links = ["base_link", "base_link_inertia", *(f"link_{i}" for i in range(6)), "tool0"]
    joints = [
        '<joint name="base_fixed" type="fixed"><parent link="base_link"/>'
        f'<child link="base_link_inertia"/><origin xyz="0 0 0" rpy="0 0 {math.pi!r}"/></joint>'
    ]
    parent = "base_link_inertia"
    for i, name in enumerate(joint_names):
        a_prev = a[i - 1] if i else 0.0
        alpha_prev = alpha[i - 1] if i else 0.0
        xyz = (a_prev, -d[i] * math.sin(alpha_prev), d[i] * math.cos(alpha_prev))
        joints.append(
            f'<joint name="{name}" type="revolute"><parent link="{parent}"/>'
            f'<child link="link_{i}"/><origin xyz="{xyz[0]!r} {xyz[1]!r} {xyz[2]!r}" '
            f'rpy="{alpha_prev!r} 0 0"/><axis xyz="0 0 1"/></joint>'
        )
        parent = f"link_{i}"
    joints.append(
        f'<joint name="tool0_fixed" type="fixed"><parent link="{parent}"/><child link="tool0"/>'
        f'<origin xyz="{a[5]!r} 0 0" rpy="{alpha[5]!r} 0 0"/></joint>'
    )
    body = "".join(f'<link name="{n}"/>' for n in links) + "".join(joints)
    return f'<?xml version="1.0"?><robot name="{preset}_urdf">{body}</robot>'
