"""What several verbs of the command line share: the program name, the initial hand-eye,
progress on stderr, the check of an output path, outputs written all or none, and the pose
source."""

from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

import numpy as np

from linelaser_calib.core.errors import CalibrationError, InputError
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.robot.kinematics import KinematicModel
from linelaser_calib.io.initial import read_initial_hand_eye
from linelaser_calib.io.kinematics import load_model

PROG = "linelaser-calib"


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
