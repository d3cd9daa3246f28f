"""What several verbs of the command line share: the program name, the initial hand-eye,
progress on stderr, the check of an output path, outputs written all or none, and the pose
source."""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import time
from pathlib import Path

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


class StderrProgress:
    """Progress on stderr, one line per stage, for long bags."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.started = time.monotonic()
        self.last_stage = ""

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        if stage != self.last_stage or done == total:
            elapsed = time.monotonic() - self.started
            print(f"  [{elapsed:6.2f} s] {stage}: {done}/{total}", file=sys.stderr)
            self.last_stage = stage


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
