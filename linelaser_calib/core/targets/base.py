"""The target protocol: what a scanned artefact provides to be calibrated against.

The pipeline (:mod:`linelaser_calib.core.pipeline`), the result files, the summary, the
report, the markers, the nodes and the CLI know targets only through this protocol and the
registry (:mod:`linelaser_calib.core.targets`); none of them tests a target's name.

Adding a target
---------------
A target is one folder ``core/targets/<name>/`` (config, feature extraction, paper solve,
refinement, target class) whose ``__init__.py`` exposes ``TARGET``, an object satisfying
:class:`Target`, plus one line in the registry ``core/targets/__init__.py``. It provides:

1. ``name`` (the ``--target`` value, the nodes' ``target`` parameter), ``title`` (human
   text), ``summary`` (one line of help), ``methods`` (``("paper", "default")`` or a subset).
2. ``config_type``: a frozen dataclass of its own settings with defaults, and ``options``:
   which of the shared user settings (:data:`SETTINGS`: ``--radius``, ``--point``, the noise
   levels, ``min_samples``, the initial hand-eye) act on it, for which methods, through which
   field of the config, and which methods need them (:class:`Option`). Any other setting is
   refused by :func:`configure` with a message naming the flag.
3. ``validate(sample, config, rng)``: one sample's :class:`~linelaser_calib.core.types.Rejection`
   or None (the collector checks live profiles with it), and ``extract(samples, config, seed,
   progress)``: the features of all samples (objects with ``index``, ``stamp_ns`` and
   ``T_base_flange``, see :class:`Feature`) and the rejections.
4. ``solve_paper`` and ``solve_default(features, config, context)``: a :class:`TargetSolution`.
   The default method is maximum likelihood with the robot's per-pose error as nuisance,
   through the shared solver :mod:`linelaser_calib.core.solver` (:func:`~linelaser_calib.core.
   solver.solve` with :func:`~linelaser_calib.core.solver.solve_with_rejection`). The
   solution carries the diagnosis: the hand-eye's 1σ (from the solver's information), what
   the poses leave undetermined in plain words (``warnings``), outliers as rejections. Raise
   DegenerateError with advice when too few features remain (:func:`rejection_digest`).
5. The model-fit check: ``check_features(features, config)`` before the solve and
   ``check_fit(solution, config)`` after it raise
   :class:`~linelaser_calib.core.errors.ModelMismatch` when the model does not fit the data
   (a feature shape the target cannot have; a residual orders of magnitude above the noise
   the solution expects, ``TargetSolution.noise_m``), naming the likely cause
   (:func:`mismatch_message`). No result is written then.
6. ``offset_cost(features, config, context)``: None, or the cost of the features re-paired
   with other flange poses (for the clock-offset search of continuous scans), and
   ``estimates_clock_offset``, True when it gives one (the collector's live estimate asks).
7. A result section class satisfying :class:`ResultSection` (its YAML key, its plain SI
   mapping, its text, its markers) and ``read_section(mapping, quality)`` that rebuilds it
   from a result file's section (raising ``ValueError`` naming the bad key).
8. Optionally, capabilities found by attribute, each with a default for a target without it:
   a ``placement_adviser`` (:func:`placement_adviser`); ``rivals`` (names of the targets whose
   full model may explain its recordings instead) and ``model_doubt(features, config)`` (why
   its own per-profile shapes put its model in doubt, or None), with which
   :func:`~linelaser_calib.core.targets.rivals.check_model` judges the whole recording, and
   ``soft_fit_check`` (True where a real profiler's shape error or a real arm's regional
   error alone may fail its fit check: a failed check that no rival explains better is then
   kept with a warning, unless it raised :class:`~..errors.GrossMismatch`);
   ``with_samples`` (features that do not depend on the poses, re-paired:
   :func:`feature_repairing`); on the section, ``surface_map`` (its surface unrolled for the
   report, :func:`surface_map`) and ``feature_distances`` with ``feature_kind`` (the paper's
   per-sample residual, :func:`feature_residuals`).

Everything is in SI units (m, rad); mm and degrees appear only in human text, labelled.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, is_dataclass, replace
from typing import Any, ClassVar, Protocol, TypeVar, cast

import numpy as np

from ..errors import InputError
from ..geometry import FloatArray
from ..robot.joint_calibration import KinematicIdentifiability, KinematicSetup
from ..robot.kinematics import JointStates, KinematicCorrections, KinematicModel
from ..types import Rejection, Sample, SampleFit

#: Progress callback: (stage name, done, total).
Progress = Callable[[str, int, int], None]

#: Shared user settings a target may take (the CLI flag / node parameter behind each):
#: ``radius_m`` (--radius, m), ``point_m`` (--point, (3,) m, base frame), ``sensor_sigma_m``
#: (--sensor-sigma, m), ``robot_sigma_t_m`` (--robot-sigma-t, m), ``robot_sigma_r_rad``
#: (--robot-sigma-r, rad), ``min_samples`` (int), ``initial`` (--initial: the initial
#: hand-eye, held by the pipeline configuration, not the target's), ``centre_side``
#: (--centre-side, ``+y``/``-y``: the sensor side of the laser plane a sphere's centre is on),
#: ``scale`` (--scale, ``auto``/``fixed``/``free``: the cylinder sensor's along-line scale).
SETTINGS = (
    "radius_m",
    "point_m",
    "centre_side",
    "sensor_sigma_m",
    "robot_sigma_t_m",
    "robot_sigma_r_rad",
    "min_samples",
    "scale",
    "initial",
)

ConfigT = TypeVar("ConfigT")


#: How the pairing begins the reason of a profile taken while the robot moved or turned.
MOVING_REASONS = ("robot moving", "robot rotating")


def _no_progress(stage: str, done: int, total: int) -> None:
    """Default progress callback: silent."""


@dataclass(frozen=True)
class Option:
    """How one shared setting acts on a target.

    Attributes
    ----------
    field : str
        Dotted path of the config field it sets (e.g. ``refine.sensor_sigma_m``); empty for
        ``initial``, which the pipeline configuration holds.
    methods : tuple of str
        Methods in which it acts; given with another method it is refused.
    required_by : tuple of str
        Methods that cannot run without it.
    why_required : str
        What the value is, for the refusal when a method needs it and it is missing
        ("set --point to <why_required>").
    """

    field: str
    methods: tuple[str, ...] = ("paper", "default")
    required_by: tuple[str, ...] = ()
    why_required: str = ""


class Feature(Protocol):
    """What a target extracts from one sample: any object with these attributes."""

    @property
    def index(self) -> int:
        """Profile index in the input stream."""
        ...

    @property
    def stamp_ns(self) -> int:
        """Profile stamp, ns."""
        ...

    @property
    def T_base_flange(self) -> FloatArray:
        """(4, 4) flange pose as paired (recorded)."""
        ...


@dataclass(frozen=True)
class Shape:
    """A marker of a result section, for RViz and Foxglove (in the result's base frame).

    Attributes
    ----------
    kind : str
        ``cylinder`` (a piece of a cylinder: ``points`` the two ends of its axis, m),
        ``sphere`` (``points`` its centre, (1, 3)), ``points`` (spheres of diameter
        2·``radius`` at ``points`` (N, 3)) or ``line`` (segments, ``points`` their ends in
        pairs).
    points : ndarray, shape (N, 3)
        m.
    radius : float
        m (line width / 2 for ``line``).
    ns : str
        Marker namespace.
    color : tuple of 4 floats
        RGBA in [0, 1].
    """

    KINDS: ClassVar[tuple[str, ...]] = ("cylinder", "sphere", "points", "line")

    kind: str
    points: FloatArray
    radius: float
    ns: str
    color: tuple[float, float, float, float] = (0.2, 0.6, 1.0, 0.5)

    def __post_init__(self) -> None:
        if self.kind not in self.KINDS:
            raise InputError(f"marker shape kind must be one of {self.KINDS}, got {self.kind!r}")


class ResultSection(Protocol):
    """The target's part of a result (e.g. the fitted cylinder, the known point).

    ``key`` is the result file's section name; :meth:`to_mapping` its plain SI content
    (lists and numbers, the base frame named); :meth:`quality_entries` further entries of the
    file's ``quality`` section; :meth:`describe` one line of human text (mm); :meth:`shapes`
    the markers drawn with the calibrated profile points; :meth:`given_settings` what a
    result used as a starting point fixes. ``key`` equals the target's ``name``.
    """

    key: ClassVar[str]
    title: ClassVar[str]

    def to_mapping(self, base_frame: str) -> dict[str, Any]:
        """Plain YAML/JSON content of the section (SI units)."""
        ...

    def quality_entries(self) -> dict[str, Any]:
        """Entries added to the result's ``quality`` section (may be empty)."""
        ...

    def describe(self, base_frame: str) -> str:
        """One line for the summary, lengths in mm."""
        ...

    def residual_kind(self, method: str) -> str:
        """What a sample's residual measures with ``method``."""
        ...

    def shapes(self, points_base: FloatArray) -> list[Shape]:
        """Markers of the section next to the calibrated points (N, 3), base frame, m."""
        ...

    def surface_distances(self, fit: SampleFit, T_base_sensor: FloatArray) -> FloatArray:
        """Signed distances (N,) in m of what the section models in one sample (its points,
        or its feature point), mapped into the base frame by ``T_base_sensor`` (4, 4), from
        the section's geometry (the self-check's held-out error)."""
        ...

    def given_settings(self) -> dict[str, Any]:
        """Shared settings (:data:`SETTINGS`) this section fixes when a result file is the
        starting point of a calibration (e.g. a taught point); usually empty."""
        ...

    def sensor_points(self, points: FloatArray) -> FloatArray:
        """Profile points (N, 3), sensor frame, m, corrected by what the calibration estimated
        of the sensor itself (the cylinder's along-line scale); usually unchanged."""
        ...


#: Robot variance factor (as a ratio of 1σ) beyond which the arm is said to be less accurate
#: than the prior (σ_t, σ_r: its repeatability) assumes.
ROBOT_PRIOR_EXCESS = 2.0
#: A fit that needs a robot pose error this many times the prior does not fit
#: (:mod:`.rivals`); nor does a fit whose residual lies this many times above what the
#: stated errors explain, where a target's fit check is soft (the line's).
MISFIT_ROBOT_EXCESS = 10.0


@dataclass(frozen=True)
class RobotError:
    """The robot's per-pose error as a default solve's pose corrections show it
    (variance-component estimate), beside the prior it was solved with.

    Attributes
    ----------
    translation_m, rotation_rad : float
        Estimated 1σ per pose and axis, m and rad.
    excess : float
        The estimate over the prior (``robot_sigma_t_m``, ``robot_sigma_r_rad``).
    """

    translation_m: float
    rotation_rad: float
    excess: float


@dataclass
class TargetSolution:
    """What a target's solve returns (indices are profile indices of the input stream).

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    section : ResultSection
    method : str
    samples_used : list of int
    rejections : list of Rejection
        Samples dropped by the solve (stage ``outlier``).
    rms_residual_m : float
    sample_residuals_m : dict of int to float
    sigma_translation_m, sigma_rotation_rad : ndarray, shape (3,), or None
        1σ of the hand-eye (flange axes, m; small angles about the sensor axes, rad).
    warnings : list of str
    history : dict of str to list of float
    sample_fits : list of SampleFit
        Of the samples used.
    noise_m : float
        The 1σ residual the model expects of a sample on clean data, m (for
        :meth:`Target.check_fit`).
    kinematics : KinematicCorrections or None
        The kinematic corrections estimated with the hand-eye, when the context asked for
        them (:attr:`SolveContext.kinematics`) and the target's default method gives them.
    identifiability : KinematicIdentifiability or None
        Which kinematic parameters the data determined (with ``kinematics``).
    subset_start : object or None
        The target's own record of its solve (its problem and state at the solution), from
        which its default solve of a subset of the used features starts when this solution
        is the context's ``warm_start``; None where the target keeps none.
    placement_sections : list of ResultSection
        The target's placement in each further recording of a joint calibration
        (:attr:`SolveContext.placements`, same order), as solved with the corrected poses.
    robot_error : RobotError or None
        The robot's per-pose error the solve estimated from its pose corrections; None where
        the solve estimates none.
    sigma_widening : ndarray, shape (6,), or None
        Factors (>= 1, [rotation, translation]) by which the 1σ above was widened because the
        profiles scatter the hand-eye more than the noise model predicts (``sample_dispersion``;
        a V's corners: ``recording_widening``, one factor); None where not checked.
        The 1σ divided by them is the noise model's.
    sigma_shared : ndarray, shape (6,), or None
        Factors (>= 1, same order) by which the 1σ above was widened, after that, for the
        robot's error that neighbouring views share (:mod:`~linelaser_calib.core.
        shared_pose`); None where not counted that way. The self-check judges the robot's
        error against the 1σ divided by both.
    sigma_model_spread : ndarray, shape (6,), or None
        The part of the 1σ above ([rotation, translation], added per axis in quadrature) that
        counts another model of the sensor the profiles cannot tell from the one solved: the
        hand-eye's move to that model's solve (:mod:`~linelaser_calib.core.model_spread`);
        None where there is none. Without it the 1σ is the statistical one, against which the
        self-check judges the data.
    converged : bool
        Whether the solve converged (False: it stopped at its iteration limit).
    """

    T_flange_sensor: FloatArray
    section: ResultSection
    method: str
    samples_used: list[int]
    rejections: list[Rejection]
    rms_residual_m: float
    sample_residuals_m: dict[int, float]
    sigma_translation_m: FloatArray | None
    sigma_rotation_rad: FloatArray | None
    warnings: list[str]
    history: dict[str, list[float]]
    sample_fits: list[SampleFit]
    noise_m: float
    kinematics: KinematicCorrections | None = None
    identifiability: KinematicIdentifiability | None = None
    subset_start: object | None = None
    placement_sections: list[ResultSection] = field(default_factory=list)
    robot_error: RobotError | None = None
    converged: bool = True
    sigma_widening: FloatArray | None = None
    sigma_shared: FloatArray | None = None
    sigma_model_spread: FloatArray | None = None


@dataclass(frozen=True)
class SolveContext:
    """What every target's solve receives besides its features and config.

    Attributes
    ----------
    initial_T_flange_sensor : ndarray, shape (4, 4), or None
        The initial hand-eye (--initial), when given.
    seed : int
        Seed of the random stages.
    rejections : list of Rejection
        Earlier rejections (pairing, features), for error messages.
    n_samples : int
        Profiles recorded: those handed to the target (before feature extraction) and those
        rejected before (pairing), for the counts of error messages.
    progress : callable
    kinematics : KinematicSetup or None
        The robot model and joint states: the default method then estimates the
        identifiable kinematic corrections with the hand-eye
        (:mod:`~linelaser_calib.core.robot.joint_calibration`), the flange pose of each feature
        being the forward kinematics of its joint vector.
    placements : sequence of Placement
        Further placements of the target scanned by the same arm and sensor (one recording
        each), for a joint calibration (``kinematics`` given): one hand-eye and one set of
        kinematic corrections from all of them, the target's placement per recording. A
        target's method that does not estimate kinematic corrections ignores them (the
        pipeline refuses that).
    warm_start : TargetSolution or None
        A default-method solution from a superset of the features (the self-check's solves
        of subsets start at the solve of all): a target may start its local solve there
        instead of at its global seed.
    screen_outliers : bool
        False: the features are a set of profiles already screened, every one to be used;
        the solve sets none aside as an outlier (its outlier rounds do not run,
        :func:`~linelaser_calib.core.solver.solve_with_rejection`'s ``screen``). Every
        solve of the self-check solves the default solve's kept profiles so: a profile's
        being an outlier is decided once, on the whole recording (why:
        :func:`linelaser_calib.core.pipeline._subset_context`).
    workers : int
        Processes a solve may use for its independent re-solves (the cylinder's two scale
        models, :func:`~linelaser_calib.core.forked.map_forked`): 2 on the command line.
    """

    initial_T_flange_sensor: FloatArray | None = None
    seed: int = 0
    rejections: Sequence[Rejection] = ()
    n_samples: int = 0
    progress: Progress = field(default=_no_progress)
    kinematics: KinematicSetup | None = None
    placements: Sequence[Placement] = ()
    warm_start: TargetSolution | None = None
    screen_outliers: bool = True
    workers: int = 1


@dataclass(frozen=True)
class Placement:
    """Another placement of the target: its features and the joint states of its recording.

    Attributes
    ----------
    features : list
        The target's features of the recording (:meth:`Target.extract`), their flange poses
        the nominal model's forward kinematics of the joint states.
    kinematics : KinematicSetup
        The same model as the main recording's, with this recording's joint states.
    """

    features: list[Any]
    kinematics: KinematicSetup


class Target(Protocol[ConfigT]):
    """A calibration target (see the module docstring for what each member must do)."""

    name: str
    title: str
    summary: str
    methods: tuple[str, ...]
    config_type: type[ConfigT]
    options: Mapping[str, Option]
    estimates_clock_offset: bool

    def validate(
        self, sample: Sample, config: ConfigT, rng: np.random.Generator
    ) -> Rejection | None:
        """Whether one sample is usable; a rejection says why not."""
        ...

    def extract(
        self,
        samples: list[Sample],
        config: ConfigT,
        seed: int,
        progress: Progress,
        workers: int = 1,
    ) -> tuple[list[Any], list[Rejection]]:
        """Features of the usable samples and the rejections of the others (each sample's
        random draws from :func:`sample_rng`; ``workers`` 2 shares the samples with a forked
        child, same outcome)."""
        ...

    def solve_paper(
        self, features: list[Any], config: ConfigT, context: SolveContext
    ) -> TargetSolution:
        """The target's paper method as published."""
        ...

    def solve_default(
        self, features: list[Any], config: ConfigT, context: SolveContext
    ) -> TargetSolution:
        """Maximum likelihood with the robot's per-pose error, via the shared solver."""
        ...

    def check_features(self, features: list[Any], config: ConfigT) -> None:
        """Raise ModelMismatch when the features have a shape the target cannot produce."""
        ...

    def check_fit(self, solution: TargetSolution, config: ConfigT) -> None:
        """Raise ModelMismatch when the solution's residual is far above the noise."""
        ...

    def offset_cost(
        self, features: list[Any], config: ConfigT, context: SolveContext
    ) -> Callable[[FloatArray], float] | None:
        """Cost of the features at other flange poses (M, 4, 4), or None if not supported."""
        ...

    def read_section(self, mapping: Mapping[str, Any], quality: Mapping[str, Any]) -> ResultSection:
        """The result section from a result file's ``key`` section (ValueError if bad)."""
        ...


#: One placement of the target for :class:`PlacementAdviser`: the profiles (or samples) of
#: its recording used (stamps, sensor-frame points in m), the recording's joint states, and
#: the target's placement there (the adviser's own object, e.g. the cylinder).
AdviceScan = tuple[Sequence[Any], JointStates, Any]


class PlacementAdviser(Protocol):
    """Optional capability of a target, its ``placement_adviser`` attribute (see
    :func:`placement_adviser`): whether another placement of the target would determine more
    of the robot's kinematics in a joint kinematic calibration."""

    def placement_of(self, section: ResultSection) -> Any | None:
        """The target's placement in the base frame held by a result section; None for a
        section of another target."""
        ...

    def placement_from_numbers(
        self, numbers: Sequence[float], radius_m: float | None
    ) -> Any | None:
        """The placement from the numbers of the planner's placement option (SI units) and
        the radius setting; None when they do not give one."""
        ...

    def advise(
        self,
        scans: Sequence[AdviceScan],
        model: KinematicModel,
        T_flange_sensor: FloatArray,
        clock_offset_s: float = 0.0,
    ) -> str:
        """The advice in words, from the placements scanned so far (the first is the main
        recording); ``model`` is the robot model (corrected where a joint calibration gave
        corrections), ``clock_offset_s`` is added to profile stamps to reach the joint
        states' clock, s."""
        ...


def placement_adviser(target: Target[Any]) -> PlacementAdviser | None:
    """The target's placement adviser; None (the default) for a target without one."""
    adviser: PlacementAdviser | None = getattr(target, "placement_adviser", None)
    return adviser


#: Optional capability of a target (see :func:`feature_repairing`): its features re-paired
#: with other samples of the same profiles (same points, other flange poses), in order.
Repairing = Callable[[list[Any], list[Sample]], list[Any]]


def feature_repairing(target: Target[Any]) -> Repairing | None:
    """The target's ``with_samples`` (:data:`Repairing`), for a target whose features do not
    depend on the flange poses: the features of a clock-offset search are then used again at
    the offset found, not extracted twice. None (the default) extracts them again."""
    repairing: Repairing | None = getattr(target, "with_samples", None)
    return repairing


@dataclass(frozen=True)
class SurfaceMap:
    """Points on a target's surface in two coordinates of that surface (the report's unrolled
    residual map).

    Attributes
    ----------
    across, along : ndarray, shape (N,)
        The two coordinates of each point, in the unit named by ``across_unit`` and
        ``along_unit`` (``rad`` or ``m``).
    across_label, along_label : str
        What each coordinate is, in words (no unit).
    across_unit, along_unit : str
        ``rad`` or ``m``.
    """

    across: FloatArray
    along: FloatArray
    across_label: str
    along_label: str
    across_unit: str = "rad"
    along_unit: str = "m"


class SurfaceMapper(Protocol):
    """Optional capability of a result section (see :func:`surface_map`): its surface
    unrolled onto two coordinates."""

    def surface_map(self, points_base: FloatArray) -> SurfaceMap:
        """Coordinates on the section's surface of points (N, 3) near it, base frame, m."""
        ...


def surface_map(section: ResultSection, points_base: FloatArray) -> SurfaceMap | None:
    """The section's unrolled coordinates of ``points_base`` (N, 3), m; None (the default)
    for a section without a surface to unroll (a point, a line)."""
    if not callable(getattr(section, "surface_map", None)):
        return None
    return cast(SurfaceMapper, section).surface_map(points_base)


class FeatureResiduals(Protocol):
    """Optional capability of a result section (see :func:`feature_residuals`): the
    distance of each sample's feature point from the fitted target, as its paper measures it
    (e.g. an ellipse centre from the cylinder axis)."""

    feature_kind: ClassVar[str]

    def feature_distances(
        self, fits: Sequence[SampleFit], T_flange_sensor: FloatArray
    ) -> FloatArray:
        """Distances (M,) in m of the fits' feature points, recorded poses."""
        ...


def feature_residuals(section: ResultSection) -> FeatureResiduals | None:
    """The section's feature residuals; None (the default) when the per-sample distances of
    :meth:`ResultSection.surface_distances` are already those of the feature point."""
    if not callable(getattr(section, "feature_distances", None)):
        return None
    return cast(FeatureResiduals, section)


def _set_path(config: Any, path: str, value: Any) -> Any:
    """``config`` (a frozen dataclass) with the dotted field ``path`` set to ``value``."""
    head, _, rest = path.partition(".")
    if not is_dataclass(config) or head not in {f.name for f in fields(config)}:
        raise InputError(f"{type(config).__name__} has no field {head!r}")
    inner = _set_path(getattr(config, head), rest, value) if rest else value
    return replace(config, **{head: inner})  # type: ignore[type-var]


def configure(
    target: Target[ConfigT],
    method: str,
    settings: Mapping[str, Any],
    labels: Mapping[str, str],
    config: ConfigT | None = None,
) -> ConfigT:
    """The target's config with the shared settings the user gave; others are refused.

    Parameters
    ----------
    target : Target
    method : str
    settings : mapping of str to value
        Only the settings the user gave (names of :data:`SETTINGS`; SI units).
    labels : mapping of str to str
        How the user names each setting (``--radius`` on the command line, ``radius`` as a
        node parameter), for the messages.
    config : target config, optional
        Start value; default the target's defaults.

    Raises
    ------
    InputError
        A setting that does not act on this target or with this method, or a method that
        needs a setting the user did not give.
    """
    if method not in target.methods:
        raise InputError(
            f"the {target.title} target has no method {method!r}; its methods: "
            + ", ".join(target.methods)
        )
    result = target.config_type() if config is None else config
    for name, value in settings.items():
        label = labels.get(name, name)
        option = target.options.get(name)
        if option is None:
            takes = sorted(labels.get(n, n) for n in target.options)
            raise InputError(
                f"{label} does not apply to the {target.title} target and would be ignored; "
                f"omit it (the {target.title} target takes {', '.join(takes) or 'none of them'})"
            )
        if method not in option.methods:
            raise InputError(
                f"{label} does not act in the {method} method of the {target.title} target "
                f"and would be ignored; omit it (it acts with method {', '.join(option.methods)})"
            )
        if option.field:
            result = _set_path(result, option.field, value)
    required = {n: o for n, o in target.options.items() if method in o.required_by}
    if any(name not in settings for name in required):
        names = [labels.get(name, name) for name in required]
        raise InputError(
            f"the {method} method of the {target.title} target needs {' and '.join(names)}: "
            "set "
            + " and ".join(
                f"{labels.get(name, name)} to {option.why_required}"
                for name, option in required.items()
            )
            + " (missing: "
            + ", ".join(labels.get(n, n) for n in required if n not in settings)
            + ")"
        )
    return result


#: The kind of every profile rejected because the robot moved (:func:`rejection_kind`).
MOVING_KIND = "pairing: robot moving or turning during the profile"


def rejection_kind(rejection: Rejection) -> str:
    """``stage: reason`` without the reason's numbers (its words up to a parenthesis or a
    colon), so that rejections of one kind are counted together; every profile rejected
    because the robot moved is :data:`MOVING_KIND`."""
    if rejection.stage == "pairing" and rejection.reason.startswith(MOVING_REASONS):
        return MOVING_KIND
    return f"{rejection.stage}: {rejection.reason.split(' (')[0].split(':')[0]}"


def rejection_digest(rejections: Sequence[Rejection], *, advise_motion: bool = True) -> str:
    """'Rejected: 3 x stage: reason; ...' (the four most common), for error messages.

    Profiles rejected because the robot moved are counted together, with advice for
    continuous scans unless ``advise_motion`` is False (the profiles kept show another
    target: more of them would not help).
    """
    if not rejections:
        return ""
    counts: dict[str, int] = {}
    moving = 0
    for r in rejections:
        key = rejection_kind(r)
        moving += key == MOVING_KIND
        counts[key] = counts.get(key, 0) + 1
    top = sorted(counts.items(), key=lambda kv: -kv[1])[:4]
    digest = "Rejected: " + "; ".join(f"{n} x {k}" for k, n in top) + ". "
    if moving and advise_motion:
        digest += (
            f"{moving} profiles were taken while the flange moved faster than the speed gate: "
            "for a scan in motion give {setting:max_linear_speed_m_s} 0 "
            "{setting:max_angular_speed_rad_s} 0 and {setting:clock_offset_s} auto (live: the "
            "collector's continuous mode). "
        )
    return digest


def plain_floats(values: Any) -> list[float]:
    """Plain Python floats of an array (for YAML/JSON sections)."""
    return [float(v) for v in np.asarray(values, dtype=np.float64).reshape(-1)]


def mm_text(values: Any) -> str:
    """``[+1.000, ...] mm`` from lengths in m."""
    return "[" + ", ".join(f"{v * 1e3:+.3f}" for v in np.ravel(values)) + "] mm"


def direction_text(values: Any) -> str:
    """``[+0.00000, ...]`` of a unit vector (no unit)."""
    return "[" + ", ".join(f"{v:+.5f}" for v in np.ravel(values)) + "]"


def read_vector(mapping: Mapping[str, Any], key: str) -> FloatArray:
    """Three finite numbers at ``key`` of a result file's section (ValueError naming it)."""
    if key not in mapping:
        raise ValueError(f"key {key} is missing")
    try:
        value = np.asarray(mapping[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"key {key} must be 3 numbers, got {mapping[key]!r}") from None
    if value.shape != (3,) or not np.all(np.isfinite(value)):
        raise ValueError(f"key {key} must be 3 finite numbers, got {mapping[key]!r}")
    return value


def mismatch_message(title: str, rms_m: float, noise_m: float, detail: str = "") -> str:
    """The refusal of a model that does not fit: what was seen and the likely causes."""
    return (
        f"the {title} model does not fit these data: the residual is {rms_m * 1e3:.3f} mm RMS, "
        f"{rms_m / noise_m:.0f} times the {noise_m * 1e3:.4f} mm the noise explains"
        + (f"; {detail}" if detail else "")
        + ". Likely causes: the scans show another target (choose it with {setting:target}); the "
        "profiles or poses are not in metres; the profile and pose clocks are not "
        "synchronised ({setting:clock_offset_s}); or the robot moved during the scans. No result "
        "was "
        "written."
    )
