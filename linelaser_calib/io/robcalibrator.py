"""Read the RobCalibrator sphere scans (a line profiler on a FANUC arm) as profiles and poses.

The folder layout (as published with RobCalibrator, MIT licence):

- ``p1.yml`` … ``pN.yml``: OpenCV FileStorage YAML (``%YAML:1.0``), key ``scan_line``: a
  flat list ``[x, 0, z, x, 0, z, …]`` in mm in the sensor's x-z laser plane. The sign and
  origin of z are the sensor's own (relative to its measuring centre); the hand-eye
  absorbs the offset.
- ``RobPoses.rob``: JSON ``{"RobPoses": [[x, y, z, w, p, r], …]}``, one per profile, in
  order: FANUC xyzwpr of the flange in the robot base, mm and degrees, R = Rz(r)·Ry(p)·Rx(w).
- ``calibration.sec``: JSON with the calibration object (``CalibObj``: ``Radius`` mm,
  ``SphCtrDirc`` ``+Y``/``-Y`` where stated) and the authors' solution (``Solution.HTM``:
  their T_flange_sensor, translation in mm).

Their 12.7 mm ball set (``data/ScanData/ball``) names its files ``1_3C_line.yml`` … and
``robpose.txt`` (rows ``x y z w p r``), and keeps its licence in the parent folder; both
layouts are read. OpenCV writes a missing point as ``.Nan``.

Everything is returned in SI units. The scans were taken step-and-shoot; the recordings
carry no time, so profile j is stamped ``epoch_ns + j`` seconds and the flange pose is
repeated a little before and after (the robot stands still).
"""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from linelaser_calib.core.geometry import project_to_so3, transform_from_rotation_translation
from linelaser_calib.core.types import FlangePose, FloatArray, Profile
from linelaser_calib.io.bags import write_bag
from linelaser_calib.io.errors import BagError
from linelaser_calib.io.results import write_reference_yaml
from linelaser_calib.io.yaml_file import yaml_problem

#: Stamp of the first profile: the authors' save time, 2023-10-31 15:31:42 (taken as UTC).
EPOCH_NS = 1_698_766_302_000_000_000
#: Time between profiles, and the offsets of the repeated flange poses around each, ns.
PROFILE_PERIOD_NS = 1_000_000_000
POSE_OFFSETS_NS = (-10_000_000, 0, 10_000_000)


def transform_from_xyzwpr(xyzwpr: Any) -> FloatArray:
    """(4, 4) transform, m, from a FANUC pose ``[x, y, z, w, p, r]`` in mm and degrees.

    R = Rz(r)·Ry(p)·Rx(w) (fixed axes x, y, z: roll w, pitch p, yaw r).
    """
    v = np.asarray(xyzwpr, dtype=np.float64)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", v[3:6], degrees=True).as_matrix()
    T[:3, 3] = v[:3] * 1e-3
    return T


@dataclass(frozen=True)
class RobCalibratorScans:
    """The scans of one folder, SI units.

    Attributes
    ----------
    profiles : list of Profile
        Points (N, 3), m, sensor frame (y = 0).
    poses : list of FlangePose
        Each flange pose repeated at :data:`POSE_OFFSETS_NS` around its profile's stamp.
    sphere_radius_m : float
    centre_side : str or None
        ``+y`` or ``-y`` (their ``SphCtrDirc``); None where they do not state it.
    T_flange_sensor_published : ndarray, shape (4, 4)
        The authors' hand-eye, m.
    """

    profiles: list[Profile]
    poses: list[FlangePose]
    sphere_radius_m: float
    centre_side: str | None
    T_flange_sensor_published: FloatArray


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BagError(f"{path} does not exist: not a RobCalibrator scan folder") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise BagError(f"cannot read {path} as JSON: {err}") from None


def _read_scan_line(path: Path) -> FloatArray:
    """The ``scan_line`` of an OpenCV FileStorage YAML file, (N, 3) in m."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise BagError(f"cannot read {path}: {err}") from None
    # PyYAML does not take OpenCV's "%YAML:1.0" directive; drop it.
    text = re.sub(r"^%YAML:1\.0\s*\n", "", text)
    # OpenCV writes a missing point as ".Nan", which YAML spells ".nan".
    text = re.sub(r"(?<![\w.])\.Nan\b", ".nan", text)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise BagError(f"{path} is not valid YAML: {yaml_problem(err)}") from None
    try:
        values = np.asarray(data["scan_line"], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as err:
        raise BagError(
            f"{path}: expected a key scan_line with [x, 0, z, ...] in mm: {err}"
        ) from None
    if values.ndim != 1 or len(values) % 3:
        raise BagError(f"{path}: scan_line must hold x, y, z triples, got {values.shape} values")
    return np.asarray(values.reshape(-1, 3) * 1e-3)


def _read_poses_mm(folder: Path) -> Any:
    """The flange poses of a folder, rows ``x y z w p r`` (mm, deg): ``RobPoses.rob``, or the
    plain text ``robpose.txt`` (one row per line) of the ball set."""
    text = folder / "robpose.txt"
    if not (folder / "RobPoses.rob").exists() and text.is_file():
        try:
            return np.loadtxt(text, dtype=np.float64, ndmin=2)
        except ValueError as err:
            raise BagError(f"{text}: expected rows of x y z w p r (mm, deg): {err}") from None
    return _read_json(folder / "RobPoses.rob")["RobPoses"]


def _profile_file(folder: Path, k: int) -> Path:
    """Profile ``k`` (from 1): ``p<k>.yml``, or ``<k>_3C_line.yml`` in the ball set."""
    plain = folder / f"p{k}.yml"
    ball = folder / f"{k}_3C_line.yml"
    return ball if not plain.exists() and ball.is_file() else plain


def read_robcalibrator(folder: str | Path) -> RobCalibratorScans:
    """Read a RobCalibrator scan folder (see the module docstring).

    Raises
    ------
    BagError
        A missing or malformed file, or profiles and poses that do not match in number.
    """
    folder = Path(folder)
    calibration = _read_json(folder / "calibration.sec")
    try:
        rows = np.asarray(_read_poses_mm(folder), dtype=np.float64)
        radius = float(calibration["CalibObj"]["Radius"]) * 1e-3
        stated = calibration["CalibObj"].get("SphCtrDirc")
        side = None if stated is None else str(stated).lower()
        htm = np.asarray(calibration["Solution"]["HTM"], dtype=np.float64)
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise BagError(
            f"{folder}: RobPoses.rob needs RobPoses [[x, y, z, w, p, r], ...] and calibration.sec "
            f"CalibObj.Radius and Solution.HTM: {err}"
        ) from None
    if (
        rows.ndim != 2
        or rows.shape[1] != 6
        or htm.shape != (4, 4)
        or side not in ("+y", "-y", None)
    ):
        raise BagError(
            f"{folder}: expected N x 6 poses, a 4 x 4 HTM and SphCtrDirc +Y or -Y; got poses "
            f"{rows.shape}, HTM {htm.shape}, SphCtrDirc {side!r}"
        )
    files = [_profile_file(folder, k + 1) for k in range(len(rows))]
    missing = [f.name for f in files if not f.is_file()]
    if missing:
        raise BagError(f"{folder}: {len(rows)} poses but no profile file {', '.join(missing)}")
    profiles: list[Profile] = []
    poses: list[FlangePose] = []
    for k, (row, path) in enumerate(zip(rows, files, strict=True)):
        stamp = EPOCH_NS + k * PROFILE_PERIOD_NS
        profiles.append(Profile(stamp, _read_scan_line(path)))
        T = transform_from_xyzwpr(row)
        poses.extend(FlangePose(stamp + offset, T) for offset in POSE_OFFSETS_NS)
    # Their matrix is stored in single precision: take the nearest rotation.
    published = transform_from_rotation_translation(project_to_so3(htm[:3, :3]), htm[:3, 3] * 1e-3)
    return RobCalibratorScans(profiles, poses, radius, side, published)


#: How the converted bag credits its source (written as the bag's README.md).
ATTRIBUTION = """# RobCalibrator sphere scans, converted

Real line-profiler scans of a sphere (radius {radius_mm:.1f} mm): an SSZN SR7140 profiler on
a FANUC arm, eye-in-hand, step-and-shoot, {count} profiles. From the public repository
GilbertPan97/RobCalibrator, folder `data/ScanData`, under the MIT licence (LICENSE, copied
beside this file). Converted to rosbag2 (SI units) by:

    {command}

- Profiles (`{profile_topic}`, sensor_msgs/PointCloud2 in `laser`): their `scan_line`,
  mm -> m. z keeps the sensor's own origin (its measuring centre); the hand-eye absorbs it.
- Flange poses (`{pose_topic}`, geometry_msgs/PoseStamped in `base_link`): their FANUC
  xyzwpr, mm/deg -> m and R = Rz(r) Ry(p) Rx(w) as a quaternion; each repeated 10 ms
  before and after its profile (the robot stood still). The recordings carry no time:
  profile j is stamped 2023-10-31 15:31:42 UTC + j s.
- `reference.yaml`: the authors' published hand-eye (their `Solution.HTM`) in the result
  file's `hand_eye` keys, SI. It is their estimate, not ground truth.
{side}
"""


def convert_robcalibrator(folder: str | Path, output: str | Path, command: str) -> Path:
    """Convert a RobCalibrator scan folder into a rosbag2 bag directory with attribution.

    Writes the bag (profiles and flange poses), ``reference.yaml`` (their hand-eye, the
    target, the settings they calibrated with as shared setting names, their sphere side
    and ``command``, the command line that made it), ``LICENSE`` (copied from the folder)
    and ``README.md`` (the attribution).

    Raises
    ------
    BagError
        Unreadable input, no LICENSE in the folder, or an existing ``output``.
    """
    folder, output = Path(folder), Path(output)
    licence = folder / "LICENSE"
    if not licence.is_file() and (folder.parent / "LICENSE").is_file():
        licence = folder.parent / "LICENSE"  # a subfolder of the repository's scans
    if not licence.is_file():
        raise BagError(
            f"{folder} has no LICENSE file: the scans travel with their licence; copy it there"
        )
    scans = read_robcalibrator(folder)
    write_bag(output, scans.profiles, scans.poses, organised=False)
    write_reference_yaml(
        output / "reference.yaml",
        scans.T_flange_sensor_published,
        extra={
            "source": "RobCalibrator (GilbertPan97/RobCalibrator, data/ScanData), MIT licence: "
            "calibration.sec Solution.HTM, the authors' estimate, not ground truth",
            "target": "sphere",
            "settings": {"radius_m": scans.sphere_radius_m},
            **({} if scans.centre_side is None else {"centre_side": scans.centre_side}),
            "conversion": {"command": command},
        },
    )
    shutil.copyfile(licence, output / "LICENSE")
    (output / "README.md").write_text(
        ATTRIBUTION.format(
            radius_mm=scans.sphere_radius_m * 1e3,
            count=len(scans.profiles),
            command=command,
            profile_topic="/profile",
            pose_topic="/flange_pose",
            side="- The sphere centre's side of the laser plane is not stated."
            if scans.centre_side is None
            else f"- The sphere centre lies on the sensor's {scans.centre_side} side of the "
            "laser plane (their\n  `SphCtrDirc`).",
        ),
        encoding="utf-8",
    )
    return output
