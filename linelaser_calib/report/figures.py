"""Matplotlib figures of a calibration result, rendered off-screen (Agg, no pyplot state).

Importing this module imports matplotlib; :func:`linelaser_calib.report.html.write_report`
imports it only after checking that matplotlib is installed. Every figure is built from a
:class:`ReportData` (the result plus its residuals, computed once by
:mod:`~..core.targets.cylinder.residuals`) and listed in :data:`FIGURES`, which the HTML page
shows in order.

Lengths are shown in mm and residuals in µm, each axis labelled with its unit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from linelaser_calib.core.geometry import FloatArray, orthonormal_basis
from linelaser_calib.core.planning import SigmaPoint
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.targets.cylinder.residuals import (
    CylinderCoordinates,
    axis_extent,
    cylinder_coordinates,
    sample_centre_distances,
    sample_points_base,
)
from linelaser_calib.report.errors import require_cylinder

matplotlib.use("Agg")

IntArray = NDArray[np.intp]

#: Figure width, inches; at :data:`DPI` the PNGs are 1000 px wide.
WIDTH_IN = 10.0
DPI = 100
#: Points drawn in the 3-D view at most (evenly strided per sample).
MAX_3D_POINTS = 6000
#: Colour map of the signed residuals (blue inside, red outside the cylinder).
RESIDUAL_CMAP = "RdBu_r"


@dataclass(frozen=True)
class ReportData:
    """A result and its residuals with the recorded flange poses.

    Attributes
    ----------
    result : CalibrationResult
    cylinder : Cylinder
        The result's fitted cylinder.
    indices : ndarray of int, shape (M,)
        Profile index of each fitted sample the solve used.
    centre_distances_m : ndarray, shape (M,)
        Ellipse centre to axis distance of each sample, m.
    points_base : list of ndarray, shape (K_j, 3)
        Each sample's inlier points in the base frame, m.
    coordinates : CylinderCoordinates
        All points (N = sum K_j) in cylinder coordinates, signed residual in m.
    sample_of_point : ndarray of int, shape (N,)
        Position (0..M-1) of each point's sample.
    """

    result: CalibrationResult
    cylinder: Cylinder
    indices: IntArray
    centre_distances_m: FloatArray
    points_base: list[FloatArray]
    coordinates: CylinderCoordinates
    sample_of_point: IntArray

    @property
    def surface_residuals_m(self) -> list[FloatArray]:
        """Signed point-to-surface distances (K_j,) of each sample, m."""
        return [
            self.coordinates.residual_m[self.sample_of_point == j] for j in range(len(self.indices))
        ]


def report_data(result: CalibrationResult) -> ReportData:
    """Map the result's sample fits into the base frame and measure their residuals."""
    cylinder = require_cylinder(result)
    fits = result.sample_fits
    T = result.T_flange_sensor
    points = [sample_points_base(f, T) for f in fits]
    stacked = np.concatenate(points) if points else np.zeros((0, 3))
    return ReportData(
        result=result,
        cylinder=cylinder,
        indices=np.array([f.index for f in fits], dtype=np.intp),
        centre_distances_m=sample_centre_distances(fits, T, cylinder),
        points_base=points,
        coordinates=cylinder_coordinates(stacked, cylinder),
        sample_of_point=np.repeat(np.arange(len(points)), [len(p) for p in points]),
    )


def _figure(height_in: float) -> Figure:
    return Figure(figsize=(WIDTH_IN, height_in), dpi=DPI, layout="constrained")


def _no_data(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")
    ax.set_xticks([])
    ax.set_yticks([])


def centre_distance_figure(data: ReportData) -> Figure:
    """Stem plot of each sample's ellipse centre to axis distance, µm (paper Fig. 10)."""
    fig = _figure(3.6)
    ax = fig.add_subplot()
    values = data.centre_distances_m * 1e6
    if len(values):
        ax.stem(data.indices, values, basefmt=" ")
        rms = float(np.sqrt(np.mean(values**2)))
        ax.axhline(rms, color="tab:red", lw=1, ls="--", label=f"RMS {rms:.1f} µm")
        ax.legend(loc="upper right")
        ax.set_ylim(bottom=0.0)
    else:
        _no_data(ax, "no fitted samples")
    ax.set_xlabel("profile index")
    ax.set_ylabel("centre to axis distance, µm")
    ax.grid(True, alpha=0.3)
    return fig


def point_residual_figure(data: ReportData) -> Figure:
    """Box plot of each sample's signed point-to-surface distances, µm."""
    fig = _figure(3.8)
    ax = fig.add_subplot()
    residuals = [r * 1e6 for r in data.surface_residuals_m]
    if residuals:
        ax.boxplot(
            residuals,
            positions=data.indices,
            widths=0.6,
            whis=(5.0, 95.0),
            flierprops={"markersize": 2, "alpha": 0.4},
            medianprops={"color": "tab:red"},
        )
        ax.axhline(0.0, color="0.3", lw=0.8)
        step = max(1, len(data.indices) // 25)
        ax.set_xticks(data.indices[::step], [str(i) for i in data.indices[::step]])
    else:
        _no_data(ax, "no fitted samples")
    ax.set_xlabel("profile index (box: quartiles, whiskers: 5 % to 95 %)")
    ax.set_ylabel("point to surface, µm (+ outside)")
    ax.grid(True, axis="y", alpha=0.3)
    return fig


def profiles_3d_figure(data: ReportData) -> Figure:
    """3-D view of the profiles in the base frame on the fitted cylinder, mm."""
    fig = _figure(7.0)
    ax = fig.add_subplot(projection="3d")
    cylinder = data.cylinder
    if data.points_base:
        per_sample = max(1, MAX_3D_POINTS // len(data.points_base))
        for j, points in enumerate(data.points_base):
            shown = points[:: max(1, int(np.ceil(len(points) / per_sample)))] * 1e3
            ax.scatter(*shown.T, s=2, color=matplotlib.colormaps["tab20"](j % 20), depthshade=False)
        centre, length = axis_extent(np.concatenate(data.points_base), cylinder)
    else:
        centre, length = np.asarray(cylinder.point), 4.0 * cylinder.radius
    d = cylinder.direction / np.linalg.norm(cylinder.direction)
    u, v = orthonormal_basis(d)
    angle, along = np.meshgrid(np.linspace(0, 2 * np.pi, 37), np.linspace(-0.5, 0.5, 9) * length)
    surface = (
        centre[:, None, None]
        + cylinder.radius * (np.cos(angle) * u[:, None, None] + np.sin(angle) * v[:, None, None])
        + along * d[:, None, None]
    ) * 1e3
    ax.plot_wireframe(*surface, color="0.55", lw=0.5, alpha=0.6)
    corners = surface.reshape(3, -1)
    half = 0.5 * float(np.max(np.ptp(corners, axis=1)))
    middle = 0.5 * (corners.min(axis=1) + corners.max(axis=1))
    ax.set_xlim(middle[0] - half, middle[0] + half)
    ax.set_ylim(middle[1] - half, middle[1] + half)
    ax.set_zlim(middle[2] - half, middle[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    frame = data.result.base_frame
    ax.set_xlabel(f"x ({frame}), mm")
    ax.set_ylabel(f"y ({frame}), mm")
    ax.set_zlabel(f"z ({frame}), mm")
    return fig


def residual_map_figure(data: ReportData) -> Figure:
    """Unrolled cylinder: angle around the axis × position along it, coloured by residual."""
    fig = _figure(4.8)
    ax = fig.add_subplot()
    c = data.coordinates
    if len(c.residual_m):
        residual_um = c.residual_m * 1e6
        limit = max(float(np.percentile(np.abs(residual_um), 99)), 1e-3)
        points = ax.scatter(
            np.degrees(c.angle_rad),
            c.along_m * 1e3,
            c=residual_um,
            s=3,
            cmap=RESIDUAL_CMAP,
            vmin=-limit,
            vmax=limit,
        )
        fig.colorbar(points, ax=ax, label="point to surface, µm (+ outside)", extend="both")
        ax.set_xlim(-180.0, 180.0)
        ax.set_xticks(np.arange(-180, 181, 45))
    else:
        _no_data(ax, "no fitted samples")
    ax.set_xlabel("angle around the axis, deg")
    ax.set_ylabel("position along the axis, mm")
    ax.grid(True, alpha=0.3)
    return fig


#: A trace spanning at least this ratio is drawn on a log axis, a flatter one on a linear axis.
LOG_SCALE_RATIO = 10.0


def _plot_traces(ax: Axes, traces: list[tuple[str, list[float]]], scale: float) -> bool:
    """Plot convergence traces (values times ``scale``) against their iteration.

    The axis is logarithmic when the positive values span at least :data:`LOG_SCALE_RATIO`
    (non-positive values are then left out), linear otherwise. Returns False when no trace
    has a value.
    """
    arrays = [(label, np.asarray(v, dtype=np.float64) * scale) for label, v in traces if len(v)]
    if not arrays:
        return False
    values = np.concatenate([y for _, y in arrays])
    positive = values[values > 0.0]
    log = len(positive) > 0 and positive.max() >= LOG_SCALE_RATIO * positive.min()
    for label, y in arrays:
        ax.plot(np.arange(len(y)), np.where(y > 0.0, y, np.nan) if log else y, lw=1.2, label=label)
    if log:
        ax.set_yscale("log")
    if len(arrays) > 1:
        ax.legend(loc="upper right", fontsize="small")
    return True


def _missing(history: dict[str, list[float]], key: str, empty: str) -> str:
    """Why a convergence trace is not drawn: ``empty`` if recorded empty, else not recorded."""
    return empty if key in history else "not recorded in this result"


def convergence_figure(data: ReportData) -> Figure:
    """PSO fitness per generation, GALM objective per outer iteration, refinement cost."""
    fig = _figure(3.6)
    history = data.result.history
    pso, galm, refine = fig.subplots(1, 3)
    if _plot_traces(pso, [("f_best", history.get("pso_best", []))], 1e6):
        pso.set_ylabel("best fitness, mm²")
    else:
        _no_data(
            pso, _missing(history, "pso_best", "no PSO generation ran\n(initial swarm accepted)")
        )
    pso.set_xlabel("PSO generation")
    pso.set_title("PSO (paper Fig. 5)")
    galm_traces = [
        ("φ (Lagrangian)", history.get("galm_phi", [])),
        ("f (centre to axis)", history.get("galm_f", [])),
    ]
    if _plot_traces(galm, galm_traces, 1e6):
        galm.set_ylabel("objective, mm²")
    else:
        _no_data(galm, _missing(history, "galm_f", "GALM did not run"))
    galm.set_xlabel("GALM outer iteration (runs joined)")
    galm.set_title("GALM (paper Fig. 6)")
    if _plot_traces(refine, [("cost", history.get("refine_cost", []))], 1.0):
        refine.set_ylabel("robust cost, dimensionless")
    else:
        _no_data(refine, f"no refinement\n(method {data.result.method})")
    refine.set_xlabel("Levenberg-Marquardt step")
    refine.set_title("ML refinement")
    for ax in (pso, galm, refine):
        ax.grid(True, which="both", alpha=0.3)
    return fig


@dataclass(frozen=True)
class FigureSpec:
    """One figure of the report: PNG file name, heading, caption and builder."""

    file: str
    title: str
    caption: str
    build: Callable[[ReportData], Figure]


#: The report's figures, in page order.
FIGURES: tuple[FigureSpec, ...] = (
    FigureSpec(
        "centre_distances.png",
        "Ellipse centre to axis distance per sample",
        "Each profile's ellipse centre, mapped into the base frame with its recorded flange "
        "pose and the calibrated hand-eye, and its distance to the fitted axis (the cylinder "
        "paper's residual, eq. 6 and Fig. 10).",
        centre_distance_figure,
    ),
    FigureSpec(
        "point_residuals.png",
        "Point to surface distance per sample",
        "Signed distance of each inlier point to the fitted cylinder surface with the recorded "
        "flange poses (no per-sample pose correction), so the robot's pose error is included.",
        point_residual_figure,
    ),
    FigureSpec(
        "profiles_3d.png",
        "Profiles in the base frame",
        "T_base_flange · T_flange_sensor · p for every inlier point, one colour per sample, on "
        "the fitted cylinder (grey).",
        profiles_3d_figure,
    ),
    FigureSpec(
        "residual_map.png",
        "Unrolled residual map",
        "The cylinder cut open: angle around the axis against position along it, each point "
        "coloured by its signed distance to the surface (red outside, blue inside). A pattern "
        "that follows the angle or the position points to a model error (wrong radius, bent "
        "axis); random colours are noise.",
        residual_map_figure,
    ),
    FigureSpec(
        "convergence.png",
        "Convergence",
        "The seed solve's PSO best fitness per generation and its GALM objective per outer "
        "iteration (the cylinder paper's Figs. 5 and 6), and the maximum-likelihood "
        "refinement's cost per accepted step (default method only). Traces spanning a factor of 10 "
        "or more are drawn on a log scale.",
        convergence_figure,
    ),
)


def sigma_curve_figure(predicted: list[SigmaPoint], achieved: list[SigmaPoint]) -> Figure:
    """The hand-eye's largest per-axis 1σ against the number of poses: predicted by the
    planner (line) and achieved by calibrations (markers); translation in mm, rotation in
    deg, log scales."""
    fig = _figure(3.6)
    panels = fig.subplots(1, 2)
    for column, (ax, scale, unit) in enumerate(
        zip(panels, (1e3, float(np.degrees(1.0))), ("mm", "deg"), strict=True)
    ):
        for series, style, label in ((predicted, "-o", "predicted"), (achieved, "s", "achieved")):
            if series:
                poses = [n for n, *_ in series]
                values = [float(np.max(sigmas[column])) * scale for _, *sigmas in series]
                ax.plot(poses, values, style, ms=4, label=label)
        ax.set_yscale("log")
        ax.set_xlabel("poses")
        ax.set_ylabel(f"largest 1 sigma of the {('translation', 'rotation')[column]}, {unit}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="upper right")
    return fig
