"""The plan file written by ``linelaser-calib plan``: the planned flange poses and the
hand-eye's predicted 1 sigma once each is taken (SI units)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from linelaser_calib.core.geometry import translation_quaternion_from_transform
from linelaser_calib.core.planning import Plan
from linelaser_calib.core.targets.base import plain_floats
from linelaser_calib.io.yaml_file import write_yaml_atomically

_PLAN_HEADER = (
    "# Planned flange poses (T_base_flange) from linelaser-calib plan, SI units (m);\n"
    "# predicted_sigma: the hand-eye's predicted 1 sigma once the pose is taken\n"
    "# (translation_m along the flange axes, rotation_rad about the sensor axes).\n"
)


def plan_to_dict(plan: Plan, base_frame: str = "base_link") -> dict[str, Any]:
    """The plan file's content: ``{frame, poses: [{translation, rotation_xyzw,
    predicted_sigma: {translation_m, rotation_rad}}]}`` (m, rad)."""
    poses = []
    for pose in plan.poses:
        translation, q_xyzw = translation_quaternion_from_transform(pose.T_base_flange)
        poses.append(
            {
                "translation": plain_floats(translation),
                "rotation_xyzw": plain_floats(q_xyzw),
                "predicted_sigma": {
                    "translation_m": plain_floats(pose.sigma_translation_m),
                    "rotation_rad": plain_floats(pose.sigma_rotation_rad),
                },
            }
        )
    return {"frame": base_frame, "poses": poses}


def write_plan_yaml(plan: Plan, path: str | Path, base_frame: str = "base_link") -> Path:
    """Write the planned poses (:func:`plan_to_dict`) to ``path`` atomically.

    Raises
    ------
    ResultFileError
        If the file cannot be written.
    """
    return write_yaml_atomically(Path(path), _PLAN_HEADER, plan_to_dict(plan, base_frame))
