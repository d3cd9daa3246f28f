"""The outcome of a calibration: :class:`CalibrationResult`, written to files in one place.

It sits above the records of :mod:`.types` and the parts that make it (the target's
result section, the self-check, the joint calibration's corrections), so that those records
import nothing above them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .pairing import ClockOffsetDiagnosis, PairingConfig
from .types import FloatArray, Rejection, SampleFit, Verdict

if TYPE_CHECKING:
    from .robot.joint_calibration import KinematicIdentifiability
    from .robot.kinematics import KinematicCorrections
    from .selfcheck import SelfCheck
    from .sigma_budget import SigmaBudget
    from .targets.base import ResultSection
    from .thinning import Thinning


@dataclass
class CalibrationResult:
    """The outcome of a calibration, written to files in one place (``linelaser_calib.io``).

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
        The hand-eye (the paper's T_EL).
    target : ResultSection
        The target's part of the result (e.g. the fitted cylinder, the known point), base
        frame; see :class:`linelaser_calib.core.targets.base.ResultSection`.
    method : str
        ``paper`` or ``default`` (maximum likelihood).
    samples_used : list of int
        Profile indices that entered the final solve.
    samples_rejected : list of Rejection
    rms_residual_m : float
        RMS residual of the final cost, m (what it measures: ``target.residual_kind``).
    sample_residuals_m : dict of int to float
        Per-sample RMS residual, m, keyed by profile index.
    uncertainty_translation_m, uncertainty_rotation_rad : ndarray, shape (3,) or None
        1-sigma of the hand-eye translation (m) and rotation (rad, small angles about the
        sensor-frame axes), when the method estimates it.
    warnings : list of str
    history : dict of str to list of float
        Convergence traces for reports (e.g. ``pso_best``, ``galm_phi``, ``refine_cost``).
    sample_fits : list of SampleFit
        The fitted samples the final solve used (not written to result files).
    clock_offset_s : float
        Offset added to the profile stamps to pair them with the poses, s.
    clock_offset_estimated : bool
        True when that offset was estimated from the data (continuous scanning).
    clock_offset_live_s, clock_offset_live_sigma_s : float or None
        The collector's live estimate of the clock offset and its 1σ, s (continuous
        scanning through the nodes); None when there is none.
    parent_frame, child_frame, base_frame : str
        Frame ids: flange, sensor and robot base.
    kinematics : KinematicCorrections or None
        The robot's kinematic corrections estimated with the hand-eye (joint calibration).
    identifiability : KinematicIdentifiability or None
        Which kinematic parameters the data determined (joint calibration).
    self_check : SelfCheck or None
        The default method's self-check (:mod:`linelaser_calib.core.selfcheck`): accuracy in
        use, halves, the model's and the widened 1σ; the uncertainty above is its widened one.
    placement_sections : list of ResultSection
        The target in each further recording of a joint calibration (same order as given),
        solved with the corrected poses (not written to result files).
    measuring_centre_depth_m : float or None
        Mean depth (sensor z, m) of the used profile points: the measuring centre (0, 0, z_c)
        of the sensor frame, where the hand-eye's 1σ is also given.
    initial_T_flange_sensor : ndarray, shape (4, 4), or None
        The initial hand-eye the calibration started from (``--initial``), when given: the
        summary says how far it was corrected (not written to result files).
    self_check_skipped_because : str
        Why no self-check ran (empty when one did, or when not known, e.g. read from a file).
    verdict : Verdict or None
        The verdict (:mod:`linelaser_calib.core.verdict`), once judged with every warning in
        (``settings.render_warnings``) or as read from a result file; None before.
    pairing : PairingConfig or None
        The pairing the profiles were paired with (speed gate, sync tolerance, clock offset),
        so that what maps the recording again pairs it alike; None where unknown (live
        pairing by the collector).
    clock_diagnosis : ClockOffsetDiagnosis or None
        Whether the residual follows the flange's velocity (:mod:`.latency`); None where the
        test did not run (step-and-shoot, an estimated offset, live pairing).
    thinning : Thinning or None
        The near-duplicate samples set aside before the solve (:mod:`.thinning`): how many
        were kept of how many, and the rule; None where every sample was kept.
    sigma_budget : SigmaBudget or None
        Where the uncertainty above comes from: the noise model's 1σ and each named widening
        (:mod:`.sigma_budget`); None without a 1σ.
    """

    T_flange_sensor: FloatArray
    target: ResultSection
    method: str
    samples_used: list[int]
    samples_rejected: list[Rejection]
    rms_residual_m: float
    sample_residuals_m: dict[int, float] = field(default_factory=dict)
    uncertainty_translation_m: FloatArray | None = None
    uncertainty_rotation_rad: FloatArray | None = None
    warnings: list[str] = field(default_factory=list)
    history: dict[str, list[float]] = field(default_factory=dict)
    sample_fits: list[SampleFit] = field(default_factory=list)
    clock_offset_s: float = 0.0
    clock_offset_estimated: bool = False
    clock_offset_live_s: float | None = None
    clock_offset_live_sigma_s: float | None = None
    parent_frame: str = "tool0"
    child_frame: str = "laser"
    base_frame: str = "base_link"
    kinematics: KinematicCorrections | None = None
    identifiability: KinematicIdentifiability | None = None
    self_check: SelfCheck | None = None
    placement_sections: list[ResultSection] = field(default_factory=list)
    measuring_centre_depth_m: float | None = None
    initial_T_flange_sensor: FloatArray | None = None
    self_check_skipped_because: str = ""
    verdict: Verdict | None = None
    pairing: PairingConfig | None = None
    clock_diagnosis: ClockOffsetDiagnosis | None = None
    thinning: Thinning | None = None
    sigma_budget: SigmaBudget | None = None
