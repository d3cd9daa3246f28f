"""What several verbs of the command line share: the program name, the result file and the
initial hand-eye as read, progress on stderr, the check of an output path, outputs written
all or none, the pose source, and the pairing a calibration was made with."""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TextIO

import numpy as np

from linelaser_calib.core.errors import CalibrationError, InputError
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.kinematics import KinematicModel
from linelaser_calib.core.targets.base import rejection_digest
from linelaser_calib.core.types import Rejection
from linelaser_calib.io.initial import read_initial_hand_eye
from linelaser_calib.io.kinematics import load_model
from linelaser_calib.io.results import read_result_yaml
from linelaser_calib.settings import Front, render, spelling

PROG = "linelaser-calib"


class HeldInterrupts:
    """Ctrl-C (SIGINT) held once a verb writes its outputs: writing them and saying so is not
    cut short, and the run ends as written (exit 0) with a note that the interrupt came too
    late. :func:`~linelaser_calib.cli.parser.main` restores the handler when the verb ends."""

    def __init__(self) -> None:
        self.caught = 0

    def hold(self) -> None:
        """From now on Ctrl-C is counted, not raised (in the main thread only, where
        signals arrive)."""
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, self._count)

    def _count(self, signum: int, frame: object) -> None:
        self.caught += 1


#: The command line's held interrupts (one process, one command).
INTERRUPTS = HeldInterrupts()


def read_calibration(path: str, what: str) -> CalibrationResult:
    """The result file ``path`` that a verb maps or exports with (``what``: the flag or
    argument naming it); what was normalised on reading goes to stderr, one line each."""
    notes: list[str] = []
    result = read_result_yaml(path, notes)
    for note in notes:
        print(f"{PROG}: warning: {what}: {note}", file=sys.stderr)
    return result


def initial_hand_eye(text: str) -> np.ndarray:
    """The hand-eye (4, 4) of ``--initial``; its warnings go to stderr."""
    try:
        initial, warnings = read_initial_hand_eye(text)
    except CalibrationError as exc:
        raise type(exc)(f"cannot use the initial hand-eye (--initial): {exc}") from exc
    for warning in warnings:
        print(f"{PROG}: warning: --initial: {warning}", file=sys.stderr)
    return initial


#: Seconds between two updates of the progress line on a terminal.
PROGRESS_INTERVAL_S = 0.5
#: Seconds a stage must have run before its rate gives an estimate of the time it has left.
ESTIMATE_AFTER_S = 1.0


class StderrProgress:
    """Progress on stderr for long recordings.

    On a terminal, one line per stage, rewritten in place at most every
    :data:`PROGRESS_INTERVAL_S`: the elapsed time, the stage, how far it is and, once it has
    run :data:`ESTIMATE_AFTER_S`, the time it has left at its rate so far. Elsewhere (stderr
    redirected, ``--progress`` given) a line when a stage starts and when it ends, so that a
    log holds no carriage returns.
    """

    def __init__(
        self,
        enabled: bool,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.enabled = enabled
        self.stream = sys.stderr if stream is None else stream
        self.live = enabled and self.stream.isatty()
        self.clock = clock
        self.started = clock()
        self.last_stage = ""
        self.stage_started = self.started
        self.stage_first = 0
        self.shown = -math.inf
        self.open_line = False

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        now = self.clock()
        new = stage != self.last_stage
        if new:
            self.last_stage, self.stage_started, self.stage_first = stage, now, done
        finished = done >= total
        if not self.live:
            if new or finished:
                print(self._text(now, stage, done, total, ""), file=self.stream)
            return
        if not (new or finished) and now - self.shown < PROGRESS_INTERVAL_S:
            return
        self.shown = now
        if new and self.open_line:
            self.stream.write("\n")
        text = self._text(now, stage, done, total, self._left(now, done, total))
        self.stream.write("\r" + text + "\033[K" + ("\n" if finished else ""))
        self.stream.flush()
        self.open_line = not finished

    def _text(self, now: float, stage: str, done: int, total: int, left: str) -> str:
        return f"  [{now - self.started:6.2f} s] {stage}: {done}/{total}{left}"

    def _left(self, now: float, done: int, total: int) -> str:
        """``, about N s left`` from the stage's rate so far, or nothing yet."""
        elapsed, progressed = now - self.stage_started, done - self.stage_first
        if done >= total or progressed <= 0 or elapsed < ESTIMATE_AFTER_S:
            return ""
        return f", about {math.ceil(elapsed / progressed * (total - done))} s left"


def check_output(path: str, what: str, *, directory: bool = False) -> Path:
    """Fail before calibrating when an output cannot be written where the user asked.

    The directory that is to hold the output must exist (a typo should not create a tree of
    directories); a file output must not be an existing directory.
    """
    target = Path(path)
    parent = target.absolute().parent
    if not parent.is_dir():
        problem = "is not a directory" if parent.exists() else "does not exist"
        raise InputError(
            f"cannot write the {what} {target}: its directory {parent} {problem}; "
            "create the directory first or fix the path"
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(
            f"cannot write the {what} {target}: its directory {parent} is not writable; "
            "choose another path"
        )
    if target.is_dir() != directory and target.exists():
        kind = "an existing directory" if target.is_dir() else "an existing file"
        raise InputError(f"cannot write the {what} {target}: it is {kind}; choose another path")
    return target


class StagedOutputs:
    """Outputs written first at hidden paths beside their own (``.NAME.staged``), then moved
    into place together by :meth:`commit`; :meth:`discard` removes them, so that a run that
    fails after writing some of its outputs leaves no file and no directory behind, and an
    earlier output stays as it was."""

    def __init__(self) -> None:
        self._moves: list[tuple[Path, Path]] = []

    def stage(self, path: str | Path) -> Path:
        """The hidden path to write the output ``path`` at (a stale one is removed)."""
        final = Path(path)
        hidden = final.with_name(f".{final.name}.staged")
        _remove(hidden)
        self._moves.append((hidden, final))
        return hidden

    def commit(self) -> None:
        """Move every staged output to its path; a directory into an existing one file by
        file (replacing files of the same name)."""
        for hidden, final in self._moves:
            if hidden.is_dir() and final.is_dir():
                for item in hidden.iterdir():
                    os.replace(item, final / item.name)
                hidden.rmdir()
            else:
                os.replace(hidden, final)
        self._moves = []

    def discard(self) -> None:
        """Remove every staged output not yet committed."""
        for hidden, _ in self._moves:
            _remove(hidden)
        self._moves = []


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def pose_source(args: argparse.Namespace) -> tuple[PoseSource, KinematicModel | None]:
    """The pose source and robot model of ``--pose-source`` and ``--kinematics``.

    Without ``--pose-source``, ``--kinematics`` selects the joint states, else the
    PoseStamped topic is the source.
    """
    if args.pose_source is None:
        args.pose_source = (
            PoseSource.POSE.value if args.kinematics is None else PoseSource.JOINT_STATES.value
        )
    source = PoseSource(args.pose_source)
    if source is PoseSource.JOINT_STATES and args.kinematics is None:
        raise InputError(
            "--pose-source joint_states computes the flange poses from the joint states "
            "through the robot's kinematic model: pass --kinematics ur5e, ur10e or a URDF file"
        )
    if source is not PoseSource.JOINT_STATES and args.kinematics is not None:
        raise InputError(
            f"--kinematics {args.kinematics} selects the robot model of the joint_states pose "
            f"source and does not apply to --pose-source {source.value}; add --pose-source "
            "joint_states or leave --kinematics out"
        )
    if args.kinematics is None:
        return source, None
    return source, load_model(
        args.kinematics, base_frame=args.base_frame, flange_frame=args.flange_frame
    )


def calibration_pairing(
    result: CalibrationResult, overrides: dict[str, float | None]
) -> tuple[PairingConfig, str]:
    """The pairing to map a recording with as the calibration did (``quality.pairing``),
    with the fields of ``overrides`` that are not None (PairingConfig field names), and a
    phrase saying which it is."""
    given = {name: float(value) for name, value in overrides.items() if value is not None}
    if result.pairing is not None:
        base, source = result.pairing, "the calibration's pairing"
    else:
        base = PairingConfig(clock_offset_s=result.clock_offset_s)
        source = "the default pairing (the calibration file has no quality.pairing)"
    pairing = replace(base, **given)
    gate = (
        "no speed gate"
        if pairing.max_linear_speed_m_s == 0.0 and pairing.max_angular_speed_rad_s == 0.0
        else f"speed gate {pairing.max_linear_speed_m_s} m/s and "
        f"{pairing.max_angular_speed_rad_s} rad/s"
    )
    changed = (
        f", {', '.join(spelling(name, Front.CLI) for name in sorted(given))} as given"
        if given
        else ""
    )
    return pairing, (
        f"paired with {source}{changed}: {gate}, sync tolerance "
        f"{pairing.sync_tolerance_s * 1e3:.1f} ms, clock offset "
        f"{pairing.clock_offset_s * 1e3:+.2f} ms"
    )


def why_not_paired(rejected: list[Rejection]) -> str:
    """The pairing rejections grouped with counts ('3 x pairing: ...; ...'), for the user."""
    digest = rejection_digest(rejected, advise_motion=False)
    return render(digest, Front.CLI).removeprefix("Rejected: ").strip()
