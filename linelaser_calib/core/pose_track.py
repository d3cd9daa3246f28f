"""A stream of flange poses held as arrays: stamps, positions and ``xyzw`` quaternions.

A robot publishes its flange pose at 125-500 Hz, so a five-minute recording holds over
100,000 of them. Held as :class:`~.types.FlangePose` records (a 4x4 matrix and a Python
object each) they take about 330 bytes a pose; a :class:`PoseTrack` takes 64 (an int64 stamp
and 7 float64). The pairing (:mod:`.pairing`) queries it at profile stamps; a pose is made a
4x4 matrix only when asked for.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from .geometry import FloatArray, matrices_from_quaternions_xyzw
from .types import BoolArray, FlangePose

IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class PoseTrack:
    """Flange poses ``T_base_flange`` of one stream, in one base frame.

    Attributes
    ----------
    stamps_ns : ndarray, shape (N,), int64
        Stamps, ns.
    translation : ndarray, shape (N, 3)
        Flange positions in the base frame, m.
    rotation_xyzw : ndarray, shape (N, 4)
        Flange orientations, unit ``xyzw`` quaternions.
    frame_id : str
        The base frame.
    """

    stamps_ns: IntArray
    translation: FloatArray
    rotation_xyzw: FloatArray
    frame_id: str = "base_link"

    def __post_init__(self) -> None:
        n = len(self.stamps_ns)
        if self.translation.shape != (n, 3) or self.rotation_xyzw.shape != (n, 4):
            raise ValueError(
                f"a pose track of {n} stamps needs translations (N, 3) and quaternions (N, 4), "
                f"got {self.translation.shape} and {self.rotation_xyzw.shape}"
            )

    @classmethod
    def empty(cls, frame_id: str = "base_link") -> PoseTrack:
        """A track without poses."""
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 4)), frame_id)

    @classmethod
    def from_transforms(
        cls, stamps_ns: ArrayLike, T_base_flange: ArrayLike, frame_id: str = "base_link"
    ) -> PoseTrack:
        """The track of transforms (N, 4, 4) at stamps (N,) ns, in their order."""
        T = np.asarray(T_base_flange, dtype=np.float64).reshape(-1, 4, 4)
        stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        rotation = Rotation.from_matrix(T[:, :3, :3]).as_quat() if len(T) else np.zeros((0, 4))
        return cls(stamps, T[:, :3, 3].copy(), rotation, frame_id)

    @classmethod
    def from_poses(cls, poses: Iterable[FlangePose], frame_id: str | None = None) -> PoseTrack:
        """The track of ``poses``, in their order; its frame is the first pose's (or
        ``frame_id``)."""
        items = list(poses)
        frame = frame_id or (items[0].frame_id if items else "base_link")
        if not items:
            return cls.empty(frame)
        return cls.from_transforms(
            [p.stamp_ns for p in items], np.stack([p.T_base_flange for p in items]), frame
        )

    @classmethod
    def of(cls, poses: PoseTrack | Iterable[FlangePose]) -> PoseTrack:
        """``poses`` as a track (itself when it is one)."""
        return poses if isinstance(poses, PoseTrack) else cls.from_poses(poses)

    @classmethod
    def concatenate(cls, tracks: Sequence[PoseTrack], frame_id: str) -> PoseTrack:
        """The poses of ``tracks`` one after the other, in frame ``frame_id``."""
        if not tracks:
            return cls.empty(frame_id)
        return cls(
            np.concatenate([t.stamps_ns for t in tracks]),
            np.concatenate([t.translation for t in tracks]),
            np.concatenate([t.rotation_xyzw for t in tracks]),
            frame_id,
        )

    def __len__(self) -> int:
        return len(self.stamps_ns)

    def __getitem__(self, index: int) -> FlangePose:
        """One pose as a record."""
        return FlangePose(int(self.stamps_ns[index]), self.transforms([index])[0], self.frame_id)

    def __iter__(self) -> Iterator[FlangePose]:
        """Each pose as a record, in order (for small tracks: a matrix is made per pose)."""
        return (self[k] for k in range(len(self)))

    def take(self, rows: NDArray[np.intp] | BoolArray | slice) -> PoseTrack:
        """The poses at ``rows`` (indices, a boolean mask or a slice), in that order."""
        return PoseTrack(
            self.stamps_ns[rows], self.translation[rows], self.rotation_xyzw[rows], self.frame_id
        )

    def transforms(self, rows: ArrayLike | None = None) -> FloatArray:
        """``T_base_flange`` (K, 4, 4) of the poses at ``rows`` (all when None), m."""
        picked = slice(None) if rows is None else np.asarray(rows, dtype=np.intp)
        q, t = self.rotation_xyzw[picked], self.translation[picked]
        T = np.zeros((len(q), 4, 4))
        T[:, :3, :3] = matrices_from_quaternions_xyzw(q) if len(q) else T[:, :3, :3]
        T[:, :3, 3] = t
        T[:, 3, 3] = 1.0
        return T

    def sorted(self) -> tuple[PoseTrack, int]:
        """The track sorted by stamp with repeated stamps dropped (the first kept), and the
        number of poses dropped; the track itself (no copy) when it is so already."""
        stamps = self.stamps_ns
        if bool(np.all(stamps[1:] > stamps[:-1])):
            return self, 0
        order = np.argsort(stamps, kind="stable")
        keep = np.ones(len(order), dtype=bool)
        keep[1:] = np.diff(stamps[order]) != 0
        return self.take(order[keep]), int(np.count_nonzero(~keep))

    def at(self, stamps_ns: ArrayLike, tolerance_ns: int) -> tuple[FloatArray, BoolArray]:
        """Flange poses at ``stamps_ns`` of a track sorted by stamp without repeats.

        At a stamp of the track, its pose. Between two poses both within ``tolerance_ns``,
        lerp on the position and slerp on the rotation (as
        :class:`scipy.spatial.transform.Slerp` computes it); with only one within it, that
        pose.

        Returns
        -------
        T_base_flange : ndarray, shape (K, 4, 4)
            Identity where no pose is within the tolerance.
        found : ndarray, shape (K,), bool
        """
        t = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        T = np.tile(np.eye(4), (len(t), 1, 1))
        n = len(self.stamps_ns)
        if n == 0:
            return T, np.zeros(len(t), dtype=bool)
        stamps = self.stamps_ns
        i = np.searchsorted(stamps, t)
        after_row, before_row = np.minimum(i, n - 1), np.maximum(i - 1, 0)
        exact = (i < n) & (stamps[after_row] == t)
        before = (i > 0) & (t - stamps[before_row] <= tolerance_ns) & ~exact
        after = (i < n) & (stamps[after_row] - t <= tolerance_ns) & ~exact
        bracket = before & after
        single = exact | (before ^ after)
        rows = np.where(exact | after, after_row, before_row)[single]
        T[single] = self.transforms(rows)
        if bracket.any():
            lo, hi = before_row[bracket], after_row[bracket]
            s = ((t[bracket] - stamps[lo]) / (stamps[hi] - stamps[lo]))[:, None]
            T[bracket, :3, 3] = (1.0 - s) * self.translation[lo] + s * self.translation[hi]
            # Slerp's own steps, on each stamp's two poses only: a Slerp over the rows used
            # also computes the steps between one stamp's poses and the next stamp's.
            start = Rotation.from_quat(self.rotation_xyzw[lo])
            step = (start.inv() * Rotation.from_quat(self.rotation_xyzw[hi])).as_rotvec()
            T[bracket, :3, :3] = (start * Rotation.from_rotvec(step * s)).as_matrix()
        return T, exact | before | after
