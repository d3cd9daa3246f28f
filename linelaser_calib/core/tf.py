"""A TF tree of static and dynamic transforms, queried for the flange pose at any stamp.

One implementation serves the offline path (``/tf`` and ``/tf_static`` read from a
recording) and the collector node (the same topics live). Every frame has at most one
parent, as in tf2. A static transform holds at every stamp; a dynamic one is a stream of
stamped transforms, each kept in a :class:`~linelaser_calib.core.pairing.PoseBuffer` and
interpolated there (lerp on position, slerp on rotation) at the queried stamp.

The flange pose ``T_base_flange`` is the product along the chain base -> common ancestor
-> flange. :meth:`TransformTree.flange_poses` turns the tree into the flange-pose stream the
pairing consumes: one pose at every stamp of a dynamic transform on the chain, every other
dynamic transform interpolated there, as tf2 would do for a lookup at that stamp.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .geometry import FloatArray, invert_transform
from .pairing import NS_PER_S, PoseBuffer
from .pose_track import PoseTrack
from .types import FlangePose

#: Frame that UR's ROS 2 driver uses for its tcp_pose_broadcaster: base_link turned 180 deg
#: about z (x and y negated).
UR_BASE_FRAME = "base"


@dataclass(frozen=True)
class StampedTransform:
    """One transform of a TF tree.

    Attributes
    ----------
    stamp_ns : int
        Header stamp, ns (ignored for a static transform).
    parent, child : str
        ``header.frame_id`` and ``child_frame_id``.
    T_parent_child : ndarray, shape (4, 4)
        Pose of ``child`` in ``parent`` (translation in m).
    """

    stamp_ns: int
    parent: str
    child: str
    T_parent_child: FloatArray


@dataclass(frozen=True)
class Edge:
    """A link of a chain: the child frame, its parent and whether it is static."""

    parent: str
    child: str
    static: bool


class TfChainError(InputError):
    """The transforms cannot link the base frame to the flange frame."""


class TransformTree:
    """Static and dynamic transforms by child frame (one parent per frame).

    Parameters
    ----------
    max_age_s : float, optional
        Dynamic transforms older than this behind the newest of their edge are dropped
        (live use); None keeps all (offline).
    """

    def __init__(self, max_age_s: float | None = None) -> None:
        self._max_age_s = max_age_s
        self._static: dict[str, tuple[str, FloatArray]] = {}
        self._dynamic: dict[str, tuple[str, PoseBuffer]] = {}
        #: Transforms that gave a frame a second parent (ignored, as tf2 does not allow it).
        self.conflicts: set[str] = set()

    def add(self, transform: StampedTransform, *, static: bool) -> None:
        """Insert one transform; a child frame keeps the parent it was first given."""
        child, parent = transform.child, transform.parent
        known = self.parent_of(child)
        if known is not None and known != parent:
            self.conflicts.add(
                f"{child} has parent {known} but transforms give it parent {parent} "
                "(ignored: a frame has one parent)"
            )
            return
        if static:
            self._static[child] = (parent, np.asarray(transform.T_parent_child, dtype=np.float64))
            return
        if child not in self._dynamic:
            self._dynamic[child] = (parent, PoseBuffer(self._max_age_s))
        self._dynamic[child][1].add(
            FlangePose(transform.stamp_ns, transform.T_parent_child, parent)
        )

    def extend(self, transforms: list[StampedTransform], *, static: bool) -> None:
        """Insert many transforms (the stamps of each dynamic edge are sorted once)."""
        if static:
            for transform in transforms:
                self.add(transform, static=True)
            return
        by_child: dict[str, list[StampedTransform]] = {}
        for transform in transforms:
            by_child.setdefault(transform.child, []).append(transform)
        for child, items in by_child.items():
            self.add(items[0], static=False)
            entry = self._dynamic.get(child)
            parent = None if entry is None else entry[0]
            if entry is not None:
                entry[1].extend(
                    [
                        FlangePose(t.stamp_ns, t.T_parent_child, t.parent)
                        for t in items[1:]
                        if t.parent == parent
                    ]
                )
            for transform in items[1:]:
                if transform.parent != parent:
                    self.add(transform, static=False)  # refused: records the conflict

    def parent_of(self, frame: str) -> str | None:
        """Parent of ``frame``, or None for a root or an unknown frame."""
        if frame in self._static:
            return self._static[frame][0]
        if frame in self._dynamic:
            return self._dynamic[frame][0]
        return None

    @property
    def frames(self) -> list[str]:
        """Every frame named by a transform, sorted."""
        names = set(self._static) | set(self._dynamic)
        names |= {p for p, _ in self._static.values()} | {p for p, _ in self._dynamic.values()}
        return sorted(names)

    def _ancestry(self, frame: str) -> list[Edge]:
        """Edges from ``frame`` up to its root."""
        edges: list[Edge] = []
        seen = {frame}
        while (parent := self.parent_of(frame)) is not None and parent not in seen:
            edges.append(Edge(parent, frame, frame in self._static))
            seen.add(parent)
            frame = parent
        return edges

    def describe(self) -> str:
        """Every frame with its parent (``child <- parent (static|dynamic)``), for messages."""
        rows = [
            f"{child} <- {parent} (static)" for child, (parent, _) in sorted(self._static.items())
        ]
        rows += [
            f"{child} <- {parent} (dynamic, {len(buffer)} stamps)"
            for child, (parent, buffer) in sorted(self._dynamic.items())
        ]
        return "; ".join(rows) or "no transforms at all"

    def chain(self, base_frame: str, flange_frame: str) -> tuple[list[Edge], list[Edge]]:
        """The edges that link ``base_frame`` to ``flange_frame``.

        Returns
        -------
        up, down : list of Edge
            ``up``: from the base frame up to the common ancestor; ``down``: from the
            flange frame up to it. ``T_base_flange = inv(prod(up)) @ prod(down)``, each
            product taken from the ancestor downwards.

        Raises
        ------
        TfChainError
            When the two frames are not in one tree, saying which frames and parents are
            present, where the chain breaks, and what to record or pass instead.
        """
        up, down = self._ancestry(base_frame), self._ancestry(flange_frame)
        base_line = [base_frame] + [e.parent for e in up]
        flange_line = [flange_frame] + [e.parent for e in down]
        common = next((f for f in flange_line if f in base_line), None)
        if common is not None:
            return up[: base_line.index(common)], down[: flange_line.index(common)]
        raise TfChainError(self._gap(base_frame, flange_frame, base_line, flange_line))

    def _gap(
        self, base_frame: str, flange_frame: str, base_line: list[str], flange_line: list[str]
    ) -> str:
        """The paragraph that explains a broken chain."""
        known = set(self.frames)

        def line(frames: list[str]) -> str:
            if frames[0] not in known:
                return f"{frames[0]} does not appear in any transform"
            return " -> ".join(frames) + f" (no transform gives {frames[-1]} a parent)"

        return (
            f"cannot build the TF chain from {base_frame} to {flange_frame}: "
            f"{line(flange_line)}; {line(base_line)}. Frames present (child <- parent): "
            f"{self.describe()}. The gap is a missing transform between {flange_line[-1]} and "
            f"{base_line[-1]}. Static transforms (/tf_static, published once and latched) are "
            "often missing from a recording: record /tf and /tf_static from the start "
            "(ros2 bag record /tf /tf_static ...), pass the frames that are linked "
            "({setting:base_frame}, {setting:flange_frame}), or use a PoseStamped flange pose "
            "topic "
            "({setting:pose_source} pose). Check the live system with "
            f"`ros2 run tf2_ros tf2_echo {base_frame} {flange_frame}`"
        )

    def _edge_at(self, edge: Edge, stamp_ns: int, tolerance_ns: int) -> FloatArray | str:
        if edge.static:
            return self._static[edge.child][1]
        return self._dynamic[edge.child][1].pose_at(stamp_ns, tolerance_ns)

    def lookup(
        self, base_frame: str, flange_frame: str, stamp_ns: int, tolerance_s: float
    ) -> FloatArray | str:
        """``T_base_flange`` (4, 4) at ``stamp_ns``, or why there is none.

        Each dynamic transform on the chain is interpolated at the stamp between its two
        bracketing transforms within ``tolerance_s`` (else the nearest within it is used).

        Raises
        ------
        TfChainError
            When the chain cannot be built (see :meth:`chain`).
        """
        up, down = self.chain(base_frame, flange_frame)
        tolerance_ns = round(tolerance_s * NS_PER_S)
        products: list[FloatArray] = []
        for edges in (up, down):
            T = np.eye(4)
            for edge in edges:
                T_edge = self._edge_at(edge, stamp_ns, tolerance_ns)
                if isinstance(T_edge, str):
                    return f"{edge.parent} -> {edge.child}: {T_edge}"
                T = T_edge @ T
            products.append(T)
        return invert_transform(products[0]) @ products[1]

    def why_no_pose(
        self, base_frame: str, flange_frame: str, stamp_ns: int, tolerance_s: float
    ) -> str | None:
        """Why the tree gives no flange pose at ``stamp_ns``, naming the frames; None when
        it gives one.

        The chain may be broken (a link never received, e.g. on /tf_static: the
        :meth:`chain` message), or a dynamic link may have nothing within ``tolerance_s``
        of the stamp: stale when its newest transform is older than that (the /tf stream
        stopped), else a gap around the stamp.
        """
        try:
            up, down = self.chain(base_frame, flange_frame)
        except TfChainError as err:
            return str(err)
        tolerance_ns = round(tolerance_s * NS_PER_S)
        problems = []
        for edge in up + down:
            if edge.static:
                continue
            buffer = self._dynamic[edge.child][1]
            latest = buffer.latest_stamp_ns
            if latest is not None and latest < stamp_ns - tolerance_ns:
                problems.append(
                    f"{edge.parent} -> {edge.child} is stale: its newest transform on /tf is "
                    f"{(stamp_ns - latest) / NS_PER_S:.3f} s older than the stamp"
                )
            elif isinstance(reason := buffer.pose_at(stamp_ns, tolerance_ns), str):
                problems.append(f"{edge.parent} -> {edge.child}: {reason}")
        return "; ".join(problems) or None

    def flange_poses(self, base_frame: str, flange_frame: str, tolerance_s: float) -> PoseTrack:
        """The flange-pose stream: ``T_base_flange`` at every stamp of a dynamic chain edge.

        Parameters
        ----------
        base_frame, flange_frame : str
        tolerance_s : float
            Largest gap, s, to the transforms of the other dynamic edges interpolated at a
            stamp; a stamp where one of them has none that near is left out.

        Returns
        -------
        PoseTrack
            Sorted by stamp, in frame ``base_frame``; one pose (at stamp 0) when the whole
            chain is static.

        Raises
        ------
        TfChainError
            When the chain cannot be built (see :meth:`chain`).
        """
        up, down = self.chain(base_frame, flange_frame)
        dynamic = [e for e in up + down if not e.static]
        stamps = sorted({s for e in dynamic for s in self._dynamic[e.child][1].stamps_ns})
        if not dynamic:
            stamps = [0]
        found = [(s, self.lookup(base_frame, flange_frame, s, tolerance_s)) for s in stamps]
        poses = [(s, T) for s, T in found if not isinstance(T, str)]
        if not poses:
            return PoseTrack.empty(base_frame)
        return PoseTrack.from_transforms(
            [s for s, _ in poses], np.stack([T for _, T in poses]), base_frame
        )


def live_flange_poses(
    tree: TransformTree,
    transforms: list[StampedTransform],
    base_frame: str,
    flange_frame: str,
    tolerance_s: float,
) -> tuple[list[FlangePose], list[str]]:
    """Add one ``/tf`` message's transforms; the flange poses it completes, and problems.

    Each stamp of a transform that moves a link of the chain gives one flange pose, the
    other dynamic links interpolated there (the live counterpart of
    :meth:`TransformTree.flange_poses`).

    Returns
    -------
    poses : list of FlangePose
        In stamp order, in ``base_frame``.
    problems : list of str
        Why no pose came (the chain is incomplete, e.g. /tf_static not received yet).
    """
    tree.extend(transforms, static=False)
    try:
        up, down = tree.chain(base_frame, flange_frame)
    except TfChainError as err:
        return [], [str(err)]
    moving = {e.child for e in up + down if not e.static}
    poses, problems = [], []
    for stamp in sorted({t.stamp_ns for t in transforms if t.child in moving}):
        T = tree.lookup(base_frame, flange_frame, stamp, tolerance_s)
        if isinstance(T, str):
            problems.append(f"no flange pose from /tf at stamp {stamp} ns: {T}")
        else:
            poses.append(FlangePose(stamp, T, base_frame))
    return poses, problems


def base_frame_warning(pose_frame: str, expected_base: str) -> str | None:
    """A warning when flange poses come in UR's ``base`` but the run expects ``base_link``.

    Parameters
    ----------
    pose_frame : str
        ``header.frame_id`` of the flange poses.
    expected_base : str
        The base frame the rest of the run names (``--base-frame``, a taught point's frame).

    Returns
    -------
    str or None
    """
    if pose_frame != UR_BASE_FRAME or expected_base == UR_BASE_FRAME:
        return None
    return (
        f"the flange poses are in frame '{UR_BASE_FRAME}' (UR's tcp_pose_broadcaster), which "
        f"is base_link turned 180 deg about z (x and y negated), while the run names "
        f"'{expected_base}': the hand-eye is unaffected, but the cylinder or point is in "
        f"'{UR_BASE_FRAME}', and a point taught in {expected_base} must have x and y negated. "
        "The pose is also the TCP set on the pendant: set the TCP to zero (the flange), or "
        "the hand-eye is the sensor's pose in that TCP frame. {setting:pose_source} tf reads the "
        "flange from /tf instead"
    )
