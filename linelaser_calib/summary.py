"""Human-readable text for a calibration result: mm and degrees, each number labelled."""

from __future__ import annotations

import numpy as np

from linelaser_calib.core.geometry import (
    quaternion_xyzw_from_matrix,
    rpy_from_matrix,
    transform_error,
)
from linelaser_calib.core.types import CalibrationResult, Rejection
from linelaser_calib.io.results import Truth


def _mm(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v * 1e3:+.3f}" for v in values) + "] mm"


def _deg(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{np.degrees(v):+.4f}" for v in values) + "] deg"


def group_rejections(rejections: list[Rejection]) -> list[tuple[str, list[int]]]:
    """(stage: reason, profile indices) pairs, most frequent first."""
    groups: dict[str, list[int]] = {}
    for r in rejections:
        groups.setdefault(f"{r.stage}: {r.reason}", []).append(r.index)
    return sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[0]))


def one_line_summary(result: CalibrationResult) -> str:
    """A single line: translation, rotation, 1 sigma, samples and residual."""
    T = result.T_flange_sensor
    text = (
        f"{result.parent_frame}->{result.child_frame} t={_mm(T[:3, 3])} "
        f"rpy={_deg(rpy_from_matrix(T[:3, :3]))}"
    )
    if result.uncertainty_translation_m is not None and result.uncertainty_rotation_rad is not None:
        text += (
            f" 1sigma {np.max(result.uncertainty_translation_m) * 1e3:.3f} mm/"
            f"{np.degrees(np.max(result.uncertainty_rotation_rad)):.4f} deg"
        )
    text += (
        f"; {len(result.samples_used)} samples, rms {result.rms_residual_m * 1e6:.1f} um"
        f" ({result.method})"
    )
    return text


def format_summary(result: CalibrationResult, truth: Truth | None = None) -> str:
    """Multi-line summary a person can act on.

    Parameters
    ----------
    result : CalibrationResult
    truth : Truth, optional
        When given (simulated bags), the error against it is printed too.
    """
    T = result.T_flange_sensor
    lines = [
        f"Hand-eye T_flange_sensor ({result.parent_frame} -> {result.child_frame}), "
        f"method {result.method}:",
        f"  translation        {_mm(T[:3, 3])}",
        f"  roll/pitch/yaw     {_deg(rpy_from_matrix(T[:3, :3]))}"
        "  (fixed axes x-y-z, R = Rz(yaw) Ry(pitch) Rx(roll))",
        "  rotation_xyzw      ["
        + ", ".join(f"{v:+.6f}" for v in quaternion_xyzw_from_matrix(T[:3, :3]))
        + "]",
    ]
    if result.uncertainty_translation_m is not None:
        lines.append(f"  1 sigma translation {_mm(result.uncertainty_translation_m)}")
    if result.uncertainty_rotation_rad is not None:
        lines.append(
            f"  1 sigma rotation   {_deg(result.uncertainty_rotation_rad)} (about sensor x, y, z)"
        )
    c = result.cylinder
    lines += [
        f"Cylinder in {result.base_frame}: point {_mm(c.point)}, direction "
        + "["
        + ", ".join(f"{v:+.5f}" for v in c.direction)
        + f"], radius {c.radius * 1e3:.3f} mm"
        + (" (estimated)" if result.radius_estimated else " (given)"),
    ]
    residuals = result.sample_residuals_m
    what = "centre-to-axis distance" if result.method == "paper" else "point-to-surface RMS"
    lines.append(
        f"Residual: rms {result.rms_residual_m * 1e6:.1f} um over "
        f"{len(result.samples_used)} samples used"
    )
    if residuals:
        values = np.array(list(residuals.values()))
        lines.append(
            f"  per-sample {what}, um: min {values.min() * 1e6:.1f}, median "
            f"{np.median(values) * 1e6:.1f}, max {values.max() * 1e6:.1f}"
        )
        cells = [f"#{i}:{v * 1e6:.1f}" for i, v in sorted(residuals.items())]
        for k in range(0, len(cells), 10):
            lines.append("    " + " ".join(cells[k : k + 10]))
    rejected = result.samples_rejected
    lines.append(f"Samples rejected: {len(rejected)}")
    for reason, indices in group_rejections(rejected):
        shown = ", ".join(str(i) for i in indices[:12]) + (" ..." if len(indices) > 12 else "")
        lines.append(f"  {len(indices)} x {reason}  [profiles {shown}]")
    for warning in result.warnings:
        lines.append(f"WARNING: {warning}")
    if truth is not None:
        rot, trans = transform_error(T, truth.T_flange_sensor)
        lines.append(
            f"Error against truth: rotation {np.degrees(rot):.4f} deg, "
            f"translation {trans * 1e3:.4f} mm"
        )
    return "\n".join(lines)
