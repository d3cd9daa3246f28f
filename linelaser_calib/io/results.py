"""Result and truth YAML files: the one place calibration results are written and read.

The result file layout (the README's "Result file")::

    hand_eye:                       # T_flange_sensor
      parent_frame: tool0
      child_frame: laser
      translation: [x, y, z]        # m
      rotation_xyzw: [x, y, z, w]
      matrix: [[...], [...], [...], [0, 0, 0, 1]]
      uncertainty:                  # 1 sigma, or null
        translation_m: [sx, sy, sz]   # of the sensor origin, flange axes
        rotation_rad: [rx, ry, rz]    # about the sensor axes
        measuring_centre_m: [0, 0, z_c]   # sensor frame: the used points' mean depth
        at_measuring_centre_m: [sx, sy, sz]   # of that point, flange axes
    cylinder: {frame: base_link, point: [x, y, z], direction: [x, y, z], radius: r}
    quality: {verdict: {level: good|use_with_care|do_not_use, reason, next_step, warnings: [ids]},
              method: ..., samples_used: N, samples_rejected: [...], rms_residual_m: ...,
              warnings: [...], accuracy_in_use_m: ..., accuracy_in_use: {...}, self_check: {...},
              pairing: {sync_tolerance_s, clock_offset_s, max_linear_speed_m_s,
                        max_angular_speed_rad_s, speed_window_s, clock_offset_diagnosis: {...}},
              thinning: {samples_kept, samples_given, neighbourhoods, neighbourhoods_thinned,
                         per_neighbourhood, cell_m, cell_rad}}

The target's section (``cylinder`` above; ``known_point``, ...) is the target's own: its
name, content and extra ``quality`` entries (the cylinder's ``radius_estimated``) come from
the result's section object (:class:`~linelaser_calib.core.targets.base.ResultSection`), and
reading finds it through the target registry. ``quality`` also carries
``samples_used_indices`` and ``sample_residuals_m`` (profile index -> RMS m). Truth files
(simulator output) use the same ``hand_eye`` and target keys (no uncertainty, no quality)
plus free extra top-level keys; the simulator's carry a ``simulation`` section (scenario,
seed, the command that regenerates them), by which :func:`truth_beside` tells them from an
unrelated ``truth.yaml``.

Values are plain Python floats, ints and strings (no numpy tags). Files are written
atomically: a temporary file in the same directory is flushed and renamed over the target,
so a reader never sees a partial file. When reading, ``translation`` and ``rotation_xyzw``
define the transform; ``matrix``, if present, must agree with them.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    check_transform,
    transform_from_rotation_translation,
    translation_quaternion_from_transform,
)
from linelaser_calib.core.latency import CLOCK_OFFSET_CODE
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.kinematics import KinematicCorrections
from linelaser_calib.core.selfcheck import sigma_at_point
from linelaser_calib.core.targets import get_target, target_names
from linelaser_calib.core.targets.base import ResultSection, plain_floats
from linelaser_calib.core.types import Level, Rejection, Verdict
from linelaser_calib.core.verdict import verdict_of
from linelaser_calib.io.errors import ResultFileError
from linelaser_calib.io.hand_eye import (
    check_translation,
    rotation_from_matrix,
    rotation_from_quaternion,
)

FloatArray = NDArray[np.float64]

#: Top-level section of the simulator's truth files (scenario, seed, command): their marker.
SIMULATION_KEY = "simulation"

#: Largest accepted difference between ``matrix`` and ``translation``/``rotation_xyzw``.
MATRIX_TOLERANCE = 1e-6

_RESULT_HEADER = (
    "# linelaser_calib result. hand_eye is T_flange_sensor (pose of child_frame in\n"
    "# parent_frame); lengths in m, angles in rad, quaternions xyzw, uncertainty 1 sigma.\n"
)
_TRUTH_HEADER = (
    "# linelaser_calib ground truth (simulator). hand_eye is T_flange_sensor;\n"
    "# lengths in m, quaternions xyzw.\n"
)


@dataclass(frozen=True)
class Truth:
    """A truth file: the true hand-eye and target, plus the whole file as read.

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    target : ResultSection
        The true target (e.g. the cylinder, the fixed point) in ``base_frame``, m.
    parent_frame, child_frame, base_frame : str
    raw : dict
        The parsed YAML, including extra keys (scenario, seed, noise, ...).
    """

    T_flange_sensor: FloatArray
    target: ResultSection
    parent_frame: str
    child_frame: str
    base_frame: str
    raw: dict[str, Any]


def _plain(value: Any) -> Any:
    """``value`` with numpy arrays and scalars turned into plain Python lists and numbers."""
    if isinstance(value, Mapping):
        return {_plain(key): _plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    return value


def _hand_eye_section(
    T_flange_sensor: ArrayLike, parent_frame: str, child_frame: str
) -> dict[str, Any]:
    T = check_transform(T_flange_sensor, 1e-4)
    translation, q_xyzw = translation_quaternion_from_transform(T)
    return {
        "parent_frame": parent_frame,
        "child_frame": child_frame,
        "translation": plain_floats(translation),
        "rotation_xyzw": plain_floats(q_xyzw),
        "matrix": [plain_floats(row) for row in T],
    }


def _target_section(section: ResultSection, frame: str) -> dict[str, Any]:
    """``{key: mapping}`` of a target section."""
    return {section.key: _plain(section.to_mapping(frame))}


#: PyYAML's safe dumper with libyaml's emitter where PyYAML was built with it: the same text
#: (3,116 YAML files compared) in a quarter of the time (a 1,600-profile result's 60 kB:
#: 0.19 -> 0.06 s, after the solve on the critical path).
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def write_yaml_atomically(path: Path, header: str, data: dict[str, Any]) -> Path:
    """Write ``header`` + YAML of ``data`` to ``path`` via a flushed temporary file."""
    try:
        text = header + yaml.dump(
            data,
            Dumper=_DUMPER,
            sort_keys=False,
            default_flow_style=None,
            width=100,
            allow_unicode=True,
        )
    except yaml.YAMLError as err:
        raise InputError(f"cannot write {path}: a value is not plain YAML data: {err}") from err
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as stream:
                os.fchmod(stream.fileno(), 0o644)
                stream.write(text)
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(tmp_name, path)
        except BaseException:
            Path(tmp_name).unlink(missing_ok=True)
            raise
    except OSError as err:
        raise ResultFileError(f"cannot write {path}: {err}") from err
    return path


def kinematics_to_dict(
    corrections: KinematicCorrections, base_frame: str, flange_frame: str
) -> dict[str, Any]:
    """The ``kinematics`` section of a result or truth file (plain YAML data, m and rad)."""
    section: dict[str, Any] = {
        "model": corrections.model,
        "base_frame": base_frame,
        "flange_frame": flange_frame,
        "corrections": {str(k): float(v) for k, v in corrections.corrections.items()},
    }
    if corrections.kept_nominal:
        section["kept_nominal"] = [str(name) for name in corrections.kept_nominal]
    return section


def _measuring_centre(result: CalibrationResult) -> dict[str, list[float]]:
    """The uncertainty's ``measuring_centre_m`` (sensor frame, m) and the 1σ there
    (``at_measuring_centre_m``, flange axes, m), when the result has both 1σ and points."""
    unc_t, unc_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
    depth = result.measuring_centre_depth_m
    if unc_t is None or unc_r is None or depth is None:
        return {}
    centre = np.array([0.0, 0.0, depth])
    return {
        "measuring_centre_m": plain_floats(centre),
        "at_measuring_centre_m": plain_floats(
            sigma_at_point(result.T_flange_sensor, unc_r, unc_t, centre)
        ),
    }


def _verdict_section(verdict: Verdict) -> dict[str, Any]:
    """``quality.verdict``: level, the deciding reason, the next step and the warnings' ids
    (the accuracy in use and why it is missing are in ``quality.accuracy_in_use*``)."""
    return {
        "level": verdict.level.value,
        "reason": verdict.reason,
        "next_step": verdict.next_step,
        "warnings": list(verdict.warning_ids),
    }


def _read_verdict(quality: _Fields) -> Verdict | None:
    """``quality.verdict`` with the accuracy in use beside it; None in a file without one."""
    if not quality.has("verdict"):
        return None
    section = quality.section("verdict")
    level = section.text("level")
    if level not in {item.value for item in Level}:
        raise section._error(
            "level", f"must be one of {', '.join(item.value for item in Level)}, got {level!r}"
        )
    accuracy = quality.data.get("accuracy_in_use")
    why = accuracy.get("not_measured_because") if isinstance(accuracy, dict) else None
    return Verdict(
        Level(level),
        section.text("reason"),
        section.text("next_step"),
        quality.number("accuracy_in_use_m") if quality.has("accuracy_in_use_m") else None,
        why if isinstance(why, str) else "",
        tuple(str(i) for i in section.items("warnings")),
    )


def _pairing_entry(result: CalibrationResult) -> dict[str, Any]:
    """``quality.pairing``: the pairing the profiles were paired with (s, m/s, rad/s) and
    the clock-offset diagnosis (:mod:`~linelaser_calib.core.latency`), when known."""
    pairing = result.pairing
    if pairing is None:
        return {}
    section: dict[str, Any] = {
        "sync_tolerance_s": float(pairing.sync_tolerance_s),
        "clock_offset_s": float(pairing.clock_offset_s),
        "max_linear_speed_m_s": float(pairing.max_linear_speed_m_s),
        "max_angular_speed_rad_s": float(pairing.max_angular_speed_rad_s),
        "speed_window_s": float(pairing.speed_window_s),
    }
    diagnosis = result.clock_diagnosis
    if diagnosis is not None:
        section["clock_offset_diagnosis"] = {
            "code": CLOCK_OFFSET_CODE,
            "significant": bool(diagnosis.significant),
            "offset_s": float(diagnosis.offset_s),
            "correction_s": float(diagnosis.correction_s),
            "sigma_s": float(diagnosis.sigma_s),
            "moving_profiles": int(diagnosis.moving),
        }
    return {"pairing": section}


def _thinning_entry(result: CalibrationResult) -> dict[str, Any]:
    """``quality.thinning``: the near-duplicate samples set aside before the solve
    (:mod:`~linelaser_calib.core.thinning`): counts and the rule (m, rad); absent where the
    rule was off."""
    thinning = result.thinning
    if thinning is None:
        return {}
    return {
        "thinning": {
            "samples_kept": int(thinning.kept),
            "samples_given": int(thinning.total),
            "neighbourhoods": int(thinning.neighbourhoods),
            "neighbourhoods_thinned": int(thinning.thinned),
            "per_neighbourhood": int(thinning.per_neighbourhood),
            "cell_m": float(thinning.cell_m),
            "cell_rad": float(thinning.cell_rad),
        }
    }


def _read_pairing(quality: _Fields) -> PairingConfig | None:
    """The result's ``quality.pairing`` (None when the file has none)."""
    if not quality.has("pairing"):
        return None
    section = quality.section("pairing")
    try:
        return PairingConfig(
            sync_tolerance_s=section.number("sync_tolerance_s"),
            clock_offset_s=section.number("clock_offset_s"),
            max_linear_speed_m_s=section.number("max_linear_speed_m_s"),
            max_angular_speed_rad_s=section.number("max_angular_speed_rad_s"),
            speed_window_s=section.number("speed_window_s"),
        )
    except ValueError as err:
        raise ResultFileError(f"{section.path}: quality.pairing: {err}") from None


def result_to_dict(result: CalibrationResult) -> dict[str, Any]:
    """The result in the contract layout (plain lists and numbers), for YAML and JSON;
    ``quality.verdict`` once judged (:func:`~linelaser_calib.settings.render_warnings`)."""
    unc_t, unc_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
    verdict = verdict_of(result)
    hand_eye = _hand_eye_section(result.T_flange_sensor, result.parent_frame, result.child_frame)
    hand_eye["uncertainty"] = (
        None
        if unc_t is None and unc_r is None
        else {
            "translation_m": None if unc_t is None else plain_floats(unc_t),
            "rotation_rad": None if unc_r is None else plain_floats(unc_r),
            **_measuring_centre(result),
        }
    )
    return {
        "hand_eye": hand_eye,
        **_target_section(result.target, result.base_frame),
        "quality": {
            **({} if result.verdict is None else {"verdict": _verdict_section(result.verdict)}),
            "method": result.method,
            "samples_used": len(result.samples_used),
            "samples_rejected": [
                {
                    "index": int(r.index),
                    "stamp_ns": int(r.stamp_ns),
                    "stage": r.stage,
                    "reason": r.reason,
                }
                for r in result.samples_rejected
            ],
            "rms_residual_m": float(result.rms_residual_m),
            "warnings": [str(w) for w in result.warnings],
            **_plain(result.target.quality_entries()),
            **(
                {
                    "accuracy_in_use_m": None,
                    "accuracy_in_use": {"not_measured_because": verdict.not_measured_because},
                }
                if result.self_check is None
                else result.self_check.quality_entries()
            ),
            "clock_offset_s": float(result.clock_offset_s),
            "clock_offset_estimated": bool(result.clock_offset_estimated),
            **{
                key: float(value)
                for key, value in (
                    ("clock_offset_live_s", result.clock_offset_live_s),
                    ("clock_offset_live_sigma_s", result.clock_offset_live_sigma_s),
                )
                if value is not None
            },
            **_pairing_entry(result),
            **_thinning_entry(result),
            "samples_used_indices": [int(i) for i in result.samples_used],
            "sample_residuals_m": {
                int(i): float(v) for i, v in sorted(result.sample_residuals_m.items())
            },
        },
        **(
            {}
            if result.kinematics is None
            else {
                "kinematics": kinematics_to_dict(
                    result.kinematics, result.base_frame, result.parent_frame
                )
            }
        ),
    }


def write_result_yaml(result: CalibrationResult, path: str | Path) -> Path:
    """Write a calibration result in the contract layout, atomically.

    Parameters
    ----------
    result : CalibrationResult
    path : str or Path
        Target file; missing parent directories are created.

    Returns
    -------
    Path

    Raises
    ------
    ResultFileError
        If the file cannot be written (nothing is left at ``path`` then).
    """
    return write_yaml_atomically(Path(path), _RESULT_HEADER, result_to_dict(result))


def write_truth_yaml(
    path: str | Path,
    T_flange_sensor: ArrayLike,
    target: ResultSection,
    *,
    parent_frame: str = "tool0",
    child_frame: str = "laser",
    base_frame: str = "base_link",
    extra: Mapping[str, Any] | None = None,
) -> Path:
    """Write a truth file (same ``hand_eye`` and target keys as a result), atomically.

    Parameters
    ----------
    path : str or Path
    T_flange_sensor : array-like, shape (4, 4)
        True hand-eye, translation in m.
    target : ResultSection
        The true target in ``base_frame``, m.
    parent_frame, child_frame, base_frame : str
    extra : mapping, optional
        Further top-level keys (scenario, seed, noise levels, ...); numpy values are
        converted to plain lists and numbers.

    Raises
    ------
    InputError
        If ``extra`` reuses ``hand_eye`` or a target key or holds values YAML cannot store.
    ResultFileError
        If the file cannot be written.
    """
    extra = dict(extra or {})
    clash = sorted({"hand_eye", *target_names()} & set(extra))
    if clash:
        raise InputError(f"extra keys {clash} would overwrite the truth itself; rename them")
    data = {
        "hand_eye": _hand_eye_section(T_flange_sensor, parent_frame, child_frame),
        **_target_section(target, base_frame),
        **_plain(extra),
    }
    return write_yaml_atomically(Path(path), _TRUTH_HEADER, data)


class _Fields:
    """Typed access to a parsed YAML mapping; every problem names the file and the key."""

    def __init__(self, path: Path, data: Any, prefix: str = "") -> None:
        if not isinstance(data, dict):
            where = prefix.rstrip(".") or "the top level"
            raise ResultFileError(f"{path}: {where} must be a mapping, got {data!r}")
        self.path, self.data, self.prefix = path, data, prefix

    def _error(self, key: object, problem: str) -> ResultFileError:
        return ResultFileError(f"{self.path}: key {self.prefix}{key} {problem}")

    def has(self, key: str) -> bool:
        return self.data.get(key) is not None

    def get(self, key: object) -> Any:
        if key not in self.data:
            raise self._error(key, "is missing")
        return self.data[key]

    def section(self, key: str) -> _Fields:
        return _Fields(self.path, self.get(key), f"{self.prefix}{key}.")

    def text(self, key: str) -> str:
        value = self.get(key)
        if not isinstance(value, str):
            raise self._error(key, f"must be a string, got {value!r}")
        return value

    def number(self, key: object) -> float:
        value = self.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self._error(key, f"must be a number, got {value!r}")
        return float(value)

    def integer(self, key: str) -> int:
        value = self.get(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self._error(key, f"must be an integer, got {value!r}")
        return value

    def array(self, key: str, shape: tuple[int, ...]) -> FloatArray:
        value = self.get(key)
        try:
            array = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise self._error(key, f"must be numbers of shape {shape}, got {value!r}") from None
        if array.shape != shape or not np.all(np.isfinite(array)):
            raise self._error(key, f"must be finite numbers of shape {shape}, got {value!r}")
        return array

    def items(self, key: str) -> list[Any]:
        """The list at ``key``; an absent or null key gives an empty list."""
        value = self.data.get(key)
        if value is None:
            return []
        if not isinstance(value, list):
            raise self._error(key, f"must be a list, got {value!r}")
        return value

    def integers(self, key: str) -> list[int]:
        values = self.items(key)
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in values):
            raise self._error(key, f"must be a list of integers, got {values!r}")
        return values

    def flag(self, key: str) -> bool:
        value = self.data.get(key, False)
        if not isinstance(value, bool):
            raise self._error(key, f"must be true or false, got {value!r}")
        return value


def _load(path: str | Path) -> tuple[Path, _Fields]:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ResultFileError(f"{path} does not exist; check the path") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ResultFileError(f"cannot read {path}: {err}") from err
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ResultFileError(f"{path} is not valid YAML: {yaml_problem(err)}") from None
    return path, _Fields(path, data)


def yaml_problem(err: yaml.YAMLError) -> str:
    """What a YAML parser found wrong and where (line and column, 1-based), without the
    parser's name for text it was handed (``"<unicode string>"``): the caller names the
    file."""
    if isinstance(err, yaml.MarkedYAMLError) and err.problem_mark is not None:
        mark = err.problem_mark
        context = f" ({err.context})" if err.context else ""
        return f"{err.problem}{context} at line {mark.line + 1}, column {mark.column + 1}"
    return str(err)


def hand_eye_transform(fields: _Fields) -> tuple[FloatArray, list[str]]:
    """``T_flange_sensor`` (4, 4) of a file's ``hand_eye`` section and what was normalised.

    The section holds ``translation`` (m) and ``rotation_xyzw``, a 4 x 4 ``matrix``, or both
    (then they must agree). Every value goes through the checks of
    :mod:`~linelaser_calib.io.hand_eye`, for every kind of file.

    Raises
    ------
    ResultFileError
        A missing or malformed key, a rotation far from one, or a translation in mm.
    """
    path = fields.path
    hand_eye = fields.section("hand_eye")
    warnings: list[str] = []
    has_pose = hand_eye.has("translation") or hand_eye.has("rotation_xyzw")
    if not has_pose and not hand_eye.has("matrix"):
        raise ResultFileError(
            f"{path}: hand_eye needs translation and rotation_xyzw, or matrix; it has "
            f"{sorted(hand_eye.data)}"
        )
    try:
        if has_pose:
            R = rotation_from_quaternion(
                hand_eye.array("rotation_xyzw", (4,)), warnings, "hand_eye.rotation_xyzw"
            )
            T = transform_from_rotation_translation(R, hand_eye.array("translation", (3,)))
            if (
                hand_eye.has("matrix")
                and np.max(np.abs(hand_eye.array("matrix", (4, 4)) - T)) > MATRIX_TOLERANCE
            ):
                raise ResultFileError(
                    f"{path}: hand_eye.matrix disagrees with hand_eye.translation and "
                    "hand_eye.rotation_xyzw; fix or delete one of them"
                )
        else:
            M = hand_eye.array("matrix", (4, 4))
            if np.max(np.abs(M[3] - [0.0, 0.0, 0.0, 1.0])) > MATRIX_TOLERANCE:
                raise ResultFileError(f"{path}: the last row of hand_eye.matrix must be 0 0 0 1")
            T = transform_from_rotation_translation(
                rotation_from_matrix(M[:3, :3], warnings, "hand_eye.matrix's rotation"), M[:3, 3]
            )
        check_translation(T[:3, 3])
    except ResultFileError:
        raise
    except InputError as err:
        raise ResultFileError(f"{path}: {err}") from None
    return T, [f"{path}: {warning}" for warning in warnings]


def _read_hand_eye(fields: _Fields, notes: list[str] | None = None) -> tuple[FloatArray, str, str]:
    """``T_flange_sensor`` (4, 4), parent frame, child frame from the ``hand_eye`` section;
    what was normalised is appended to ``notes`` (when given)."""
    T, normalised = hand_eye_transform(fields)
    if notes is not None:
        notes.extend(normalised)
    hand_eye = fields.section("hand_eye")
    return T, hand_eye.text("parent_frame"), hand_eye.text("child_frame")


def _read_target(fields: _Fields) -> tuple[ResultSection, str]:
    """The target section (the first registered target whose key is present) and its frame."""
    quality = fields.data.get("quality")
    quality = quality if isinstance(quality, dict) else {}
    for name in target_names():
        if fields.has(name):
            section = fields.section(name)
            try:
                target = get_target(name).read_section(section.data, quality)
            except ValueError as err:
                raise ResultFileError(f"{fields.path}: {name}: {err}") from None
            return target, section.text("frame")
    raise ResultFileError(
        f"{fields.path}: no target section: a result or truth file needs one of the keys "
        + ", ".join(target_names())
    )


def _read_uncertainty(hand_eye: _Fields, key: str) -> FloatArray | None:
    if not hand_eye.has("uncertainty"):
        return None
    uncertainty = hand_eye.section("uncertainty")
    return uncertainty.array(key, (3,)) if uncertainty.has(key) else None


def _read_measuring_centre(hand_eye: _Fields) -> float | None:
    """The depth (m) of the uncertainty's ``measuring_centre_m``, None without one."""
    centre = _read_uncertainty(hand_eye, "measuring_centre_m")
    return None if centre is None else float(centre[2])


def read_result_yaml(path: str | Path, notes: list[str] | None = None) -> CalibrationResult:
    """Read a result file written by :func:`write_result_yaml` (or by hand, same keys).

    A hand-eye rotation normalised on reading (:mod:`~linelaser_calib.io.hand_eye`) is said
    in one line each appended to ``notes``, when given; every verb that reads a result
    passes them on to the user.

    ``samples_used`` is restored from ``quality.samples_used_indices`` (empty if absent);
    optional keys (``warnings``, ``samples_rejected``, ``uncertainty``, ...) default to empty.
    Convergence ``history`` is not stored in the file.

    Raises
    ------
    ResultFileError
        Missing file, invalid YAML, or a missing or malformed key (named in the message).
    """
    path, fields = _load(path)
    T, parent_frame, child_frame = _read_hand_eye(fields, notes)
    target, base_frame = _read_target(fields)
    hand_eye = fields.section("hand_eye")
    quality = fields.section("quality")
    rejected = []
    for i, entry in enumerate(quality.items("samples_rejected")):
        item = _Fields(path, entry, f"quality.samples_rejected[{i}].")
        rejected.append(
            Rejection(
                item.integer("index"),
                item.integer("stamp_ns"),
                item.text("stage"),
                item.text("reason"),
            )
        )
    residuals: dict[int, float] = {}
    if quality.has("sample_residuals_m"):
        section = quality.section("sample_residuals_m")
        for key in section.data:
            if isinstance(key, bool) or not isinstance(key, int):
                raise ResultFileError(
                    f"{path}: key quality.sample_residuals_m must map profile indices "
                    f"(integers) to m, got key {key!r}"
                )
            residuals[key] = section.number(key)
    return CalibrationResult(
        T_flange_sensor=T,
        target=target,
        method=quality.text("method"),
        samples_used=quality.integers("samples_used_indices"),
        samples_rejected=rejected,
        rms_residual_m=quality.number("rms_residual_m"),
        sample_residuals_m=residuals,
        uncertainty_translation_m=_read_uncertainty(hand_eye, "translation_m"),
        uncertainty_rotation_rad=_read_uncertainty(hand_eye, "rotation_rad"),
        measuring_centre_depth_m=_read_measuring_centre(hand_eye),
        clock_offset_s=quality.number("clock_offset_s") if quality.has("clock_offset_s") else 0.0,
        clock_offset_estimated=quality.flag("clock_offset_estimated"),
        clock_offset_live_s=(
            quality.number("clock_offset_live_s") if quality.has("clock_offset_live_s") else None
        ),
        clock_offset_live_sigma_s=(
            quality.number("clock_offset_live_sigma_s")
            if quality.has("clock_offset_live_sigma_s")
            else None
        ),
        warnings=[str(w) for w in quality.items("warnings")],
        verdict=_read_verdict(quality),
        pairing=_read_pairing(quality),
        parent_frame=parent_frame,
        child_frame=child_frame,
        base_frame=base_frame,
    )


def read_truth_yaml(path: str | Path) -> Truth:
    """Read a truth file written by :func:`write_truth_yaml` (``bags/*/truth.yaml``).

    Raises
    ------
    ResultFileError
        Missing file, invalid YAML, or a missing or malformed key.
    """
    path, fields = _load(path)
    T, parent_frame, child_frame = _read_hand_eye(fields)
    target, base_frame = _read_target(fields)
    return Truth(T, target, parent_frame, child_frame, base_frame, fields.data)


def truth_beside(bag: str | Path) -> tuple[Truth | None, str]:
    """The simulator's ``truth.yaml`` in a bag directory, if it holds one.

    A ``truth.yaml`` without the simulator's ``simulation`` section (another tool's file, a
    note), or one that cannot be read, is not an error: the truth only serves to compare.

    Parameters
    ----------
    bag : str or Path
        A bag directory (a file path has no truth beside it).

    Returns
    -------
    truth : Truth or None
    note : str
        Empty, or one line saying why a ``truth.yaml`` that is there is not used.
    """
    path = Path(bag) / "truth.yaml"
    if not path.is_file():
        return None, ""
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        data = None
    simulation = data.get(SIMULATION_KEY) if isinstance(data, dict) else None
    if not (isinstance(simulation, dict) and {"scenario", "seed"} <= set(simulation)):
        return None, (
            f"{path} is not a truth file of linelaser-calib simulate (no {SIMULATION_KEY} "
            "section with scenario and seed); not compared"
        )
    try:
        return read_truth_yaml(path), ""
    except ResultFileError as err:
        return None, f"{err}; the truth file is not compared"


_REFERENCE_HEADER = (
    "# A hand-eye from elsewhere (not ground truth), for comparison. hand_eye is\n"
    "# T_flange_sensor; lengths in m, quaternions xyzw.\n"
)


def write_reference_yaml(
    path: str | Path,
    T_flange_sensor: ArrayLike,
    *,
    parent_frame: str = "tool0",
    child_frame: str = "laser",
    extra: Mapping[str, Any] | None = None,
) -> Path:
    """Write another tool's hand-eye in the result's ``hand_eye`` keys (SI), atomically.

    Parameters
    ----------
    path : str or Path
    T_flange_sensor : array-like, shape (4, 4)
        Translation in m.
    parent_frame, child_frame : str
    extra : mapping, optional
        Further top-level keys (where the hand-eye comes from); not ``hand_eye``.

    Raises
    ------
    InputError
        If ``extra`` holds ``hand_eye`` or values YAML cannot store.
    ResultFileError
        If the file cannot be written.
    """
    extra = dict(extra or {})
    if "hand_eye" in extra:
        raise InputError("extra must not hold hand_eye, the reference itself")
    data = {"hand_eye": _hand_eye_section(T_flange_sensor, parent_frame, child_frame)}
    return write_yaml_atomically(Path(path), _REFERENCE_HEADER, {**data, **_plain(extra)})


def read_reference_yaml(path: str | Path) -> tuple[FloatArray, dict[str, Any]]:
    """The hand-eye (4, 4) of a file with a ``hand_eye`` section, and the whole file as read.

    Raises
    ------
    ResultFileError
        Missing file, invalid YAML, or a missing or malformed ``hand_eye`` key.
    """
    _, fields = _load(path)
    T, _, _ = _read_hand_eye(fields)
    return T, fields.data
