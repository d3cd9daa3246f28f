"""Robot models from files and names, and the ``kinematics`` section of result files.

``--kinematics`` takes a preset name (``ur5e``, ``ur10e``: the nominal DH tables) or a URDF
file. A URDF is parsed with the standard library's XML parser: the chain of joints from
``base_frame`` to ``flange_frame`` (parent/child links), each joint's ``origin`` (xyz in m,
rpy in rad; absent means zero), ``axis`` (default x, as URDF says) and type. Joint
``mimic``, limits and dynamics are not needed for the flange pose and are not read.

The ``kinematics`` section of a result (or truth) file::

    kinematics:
      model: ur5e                  # the preset or URDF file the corrections apply to
      base_frame: base_link
      flange_frame: tool0
      corrections:                 # added to the nominal parameter; m for lengths, rad for angles
        shoulder_pan_joint.offset: 1.2e-4
        elbow_joint.a: -3.0e-4
      kept_nominal: [wrist_3_joint.d]  # optional: what a calibration could not determine
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.robot.kinematics import (
    UR_DH,
    JointSpec,
    KinematicCorrections,
    KinematicModel,
    model_from_preset,
    urdf_model,
)
from linelaser_calib.io.errors import ResultFileError
from linelaser_calib.io.results import kinematics_to_dict
from linelaser_calib.io.yaml_file import load_fields

SECTION = "kinematics"


def _triple(element: ET.Element | None, key: str, default: str, joint: str) -> tuple[float, ...]:
    text = default if element is None else element.get(key, default)
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        values = ()
    if len(values) != 3 or not np.all(np.isfinite(values)):
        raise InputError(f"joint {joint!r}: {key}={text!r} must be three numbers")
    return values


def model_from_urdf(
    text: str,
    *,
    base_frame: str = "base_link",
    flange_frame: str = "tool0",
    name: str | None = None,
) -> KinematicModel:
    """The serial chain ``base_frame`` -> ``flange_frame`` of a URDF document.

    Raises
    ------
    InputError
        Not XML, not a ``<robot>``, a frame missing, or no chain between the two frames
        (the links found and where the chain stopped are named).
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        raise InputError(f"the URDF is not valid XML: {err}") from None
    if root.tag != "robot":
        raise InputError(f"the URDF's root element is <{root.tag}>, expected <robot>")
    by_child: dict[str, ET.Element] = {}
    for joint in root.iter("joint"):
        parent, child = joint.find("parent"), joint.find("child")
        if parent is not None and child is not None and child.get("link"):
            by_child[str(child.get("link"))] = joint
    links = sorted({str(link.get("name")) for link in root.iter("link")})
    for frame in (base_frame, flange_frame):
        if frame not in links:
            raise InputError(
                f"the URDF has no link {frame!r}; its links are {links}. Pass the base and "
                "flange frames of the robot"
            )
    chain: list[JointSpec] = []
    link, seen = flange_frame, set()
    while link != base_frame:
        found = by_child.get(link)
        if found is None or link in seen:
            raise InputError(
                f"the URDF has no chain from {base_frame!r} to {flange_frame!r}: it stops at "
                f"link {link!r}, which no joint has as child"
            )
        joint_name = str(found.get("name"))
        origin = found.find("origin")
        xyz = _triple(origin, "xyz", "0 0 0", joint_name)
        rpy = _triple(origin, "rpy", "0 0 0", joint_name)
        axis = _triple(found.find("axis"), "xyz", "1 0 0", joint_name)
        chain.append(
            JointSpec(
                joint_name,
                str(found.get("type")),
                (xyz[0], xyz[1], xyz[2]),
                (rpy[0], rpy[1], rpy[2]),
                (axis[0], axis[1], axis[2]),
            )
        )
        seen.add(link)
        parent = found.find("parent")
        link = "" if parent is None else str(parent.get("link"))
    chain.reverse()
    robot = name or str(root.get("name") or "urdf")
    return urdf_model(robot, chain, base_frame=base_frame, flange_frame=flange_frame)


#: File name endings of a robot description: a name ending so is a file, never a preset.
URDF_SUFFIXES = (".urdf", ".xacro", ".xml")


def load_model(
    spec: str, *, base_frame: str = "base_link", flange_frame: str = "tool0"
) -> KinematicModel:
    """The robot model named by ``--kinematics``: a preset name, a URDF file or URDF text.

    A URDF model is named by its file path, so that a result's ``kinematics.model`` finds
    it again. URDF text (``spec`` starting with ``<``, e.g. the value of a
    ``robot_description`` parameter) gives a model named after its ``<robot>``.

    Raises
    ------
    InputError
        Unknown preset and no such file, or an unusable URDF.
    """
    if spec in UR_DH:
        return model_from_preset(spec)
    if spec.lstrip().startswith("<"):
        try:
            return model_from_urdf(spec, base_frame=base_frame, flange_frame=flange_frame)
        except InputError as err:
            raise InputError(f"the URDF text: {err}") from None
    path = Path(spec)
    presets = ", ".join(sorted(UR_DH))
    if path.is_dir():
        raise InputError(f"the robot model {spec} is a directory; give a URDF file or a preset")
    if not path.exists() and (path.suffix in URDF_SUFFIXES or len(path.parts) > 1):
        raise InputError(
            f"the robot model {spec}: no such file; give an existing URDF file, a preset "
            f"({presets}) or the URDF text"
        )
    if not path.is_file():
        raise InputError(
            f"--kinematics {spec!r} is neither a preset ({presets}) nor a "
            "URDF file nor URDF text; give one of them"
        )
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"cannot read the URDF {path}: {err}") from None
    try:
        return model_from_urdf(text, base_frame=base_frame, flange_frame=flange_frame, name=spec)
    except InputError as err:
        raise InputError(f"URDF {path}: {err}") from None


def kinematics_section(corrections: KinematicCorrections, model: KinematicModel) -> dict[str, Any]:
    """The ``kinematics`` section of a result or truth file (plain YAML data)."""
    return kinematics_to_dict(corrections, model.base_frame, model.flange_frame)


def read_kinematics(path: str | Path) -> KinematicCorrections | None:
    """The ``kinematics`` section of a result file, or None when it has none.

    Raises
    ------
    ResultFileError
        Unreadable file or a malformed section (the key is named).
    """
    file_path, fields = load_fields(path)
    if not fields.has(SECTION):
        return None
    section = fields.section(SECTION)
    raw = section.get("corrections")
    if not isinstance(raw, Mapping):
        raise ResultFileError(
            f"{file_path}: key {SECTION}.corrections must map parameter names to numbers"
        )
    corrections = {}
    for key in raw:
        corrections[str(key)] = section.section("corrections").number(key)
    kept = section.get("kept_nominal") if section.has("kept_nominal") else []
    if not isinstance(kept, list) or not all(isinstance(name, str) for name in kept):
        raise ResultFileError(f"{file_path}: key {SECTION}.kept_nominal must list parameter names")
    return KinematicCorrections(section.text("model"), corrections, tuple(kept))
