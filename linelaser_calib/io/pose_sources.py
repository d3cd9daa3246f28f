"""Flange poses of a recording, from the chosen pose source (``PoseSource``).

Each source is one function ``(bag, request) -> FlangePoses`` in :data:`POSE_SOURCES`;
the profiles always come from :func:`~linelaser_calib.io.bags.read_bag`.

- ``pose``: the PoseStamped topic ``read_bag`` read.
- ``tf``: ``/tf`` and ``/tf_static`` (``tf2_msgs/msg/TFMessage``) read into a
  :class:`~linelaser_calib.core.tf.TransformTree`, and the chain base frame -> flange frame
  evaluated at every stamp of its dynamic transforms.
- ``joint_states``: the ``sensor_msgs/msg/JointState`` stream of the bag through the robot
  model (:func:`~linelaser_calib.core.robot.kinematics.flange_poses_from_joint_states`); each
  flange pose keeps its joint state's stamp, so that pairing interpolates between them as
  between recorded poses.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.pose_track import PoseTrack
from linelaser_calib.core.robot.kinematics import (
    JointStates,
    KinematicModel,
    flange_poses_from_joint_states,
)
from linelaser_calib.core.tf import StampedTransform, TransformTree, base_frame_warning
from linelaser_calib.io.bags import (
    TF_STATIC_TOPIC,
    TF_TOPIC,
    TF_TYPE,
    BagContents,
    SkippedMessage,
    bag_parts,
    decode_message,
    open_part,
    raw_messages,
    read_joint_states,
    reading_store,
)
from linelaser_calib.io.errors import BagError
from msg_adapters import stamp_ns_from_msg, stamped_transforms_from_msgs


@dataclass(frozen=True)
class PoseRequest:
    """What a pose source needs besides the bag.

    Attributes
    ----------
    base_frame, flange_frame : str
        The robot base and the flange (``tf``: the two ends of the chain).
    sync_tolerance_s : float
        Largest gap to a dynamic transform interpolated at a stamp, s.
    model : KinematicModel or None
        ``joint_states``: the robot's kinematic model (required).
    joint_state_topic : str or None
        ``joint_states``: the JointState topic (default ``/joint_states``, else the only one).
    """

    base_frame: str = "base_link"
    flange_frame: str = "tool0"
    sync_tolerance_s: float = 0.02
    model: KinematicModel | None = None
    joint_state_topic: str | None = None


@dataclass(frozen=True)
class FlangePoses:
    """The flange-pose stream of a run and where it came from.

    Attributes
    ----------
    poses : PoseTrack
        ``T_base_flange`` in m, sorted by stamp.
    base_frame : str
        Frame of the poses (the result's base frame).
    description : str
        Where they came from, for the printed input line (e.g. ``'1200 on /flange_pose'``).
    warnings : list of str
        Things the user should know (they join the result's warnings).
    joint_states : JointStates or None
        ``joint_states``: the stream the poses were computed from.
    """

    poses: PoseTrack
    base_frame: str
    description: str
    warnings: list[str] = field(default_factory=list)
    joint_states: JointStates | None = None


@dataclass(frozen=True)
class TfRecording:
    """``/tf`` and ``/tf_static`` of a recording.

    Attributes
    ----------
    tree : TransformTree
    dynamic_count, static_count : int
        Transforms read from ``/tf`` and from ``/tf_static``.
    skipped : list of SkippedMessage
        Messages or transforms that could not be used, with the reason.
    """

    tree: TransformTree
    dynamic_count: int
    static_count: int
    skipped: list[SkippedMessage]


def read_tf(path: str | Path) -> TfRecording:
    """Read ``/tf`` and ``/tf_static`` of a bag into a :class:`TransformTree`.

    Raises
    ------
    BagError
        When the bag has neither topic, or it cannot be read.
    """
    bag = Path(path)
    dynamic: list[StampedTransform] = []
    static: list[StampedTransform] = []
    skipped: list[SkippedMessage] = []
    topics: set[str] = set()
    items: list[tuple[str, list[Any]]] = []
    for part in bag_parts(bag):
        with open_part(part, bag) as reader:
            connections = [
                c
                for c in reader.connections
                if c.msgtype == TF_TYPE and c.topic in (TF_TOPIC, TF_STATIC_TOPIC)
            ]
            topics |= {c.topic for c in reader.connections}
            store = reading_store(connections)
            for conn, log_ns, raw in raw_messages(reader, connections, bag, part):
                msg = decode_message(store, conn.topic, TF_TYPE, log_ns, raw)
                if isinstance(msg, SkippedMessage):
                    skipped.append(msg)
                    continue
                items.append((conn.topic, msg.transforms))
    topic_of = [topic for topic, transforms in items for _ in transforms]
    messages = [m for _, transforms in items for m in transforms]
    for topic, msg, converted in zip(
        topic_of, messages, stamped_transforms_from_msgs(messages), strict=True
    ):
        if isinstance(converted, str):
            skipped.append(SkippedMessage(topic, stamp_ns_from_msg(msg.header.stamp), converted))
        else:
            (static if topic == TF_STATIC_TOPIC else dynamic).append(converted)
    if not dynamic and not static:
        raise BagError(
            f"bag {bag} holds no {TF_TYPE} on {TF_TOPIC} or {TF_STATIC_TOPIC} (its topics: "
            f"{', '.join(sorted(topics)) or 'none'}); record /tf and /tf_static, or use the "
            "PoseStamped flange pose topic (--pose-source pose)"
        )
    tree = TransformTree()
    tree.extend(static, static=True)
    tree.extend(dynamic, static=False)
    return TfRecording(tree, len(dynamic), len(static), skipped)


def poses_from_pose_topic(bag: BagContents, request: PoseRequest) -> FlangePoses:
    """The PoseStamped flange poses ``read_bag`` read, with the UR ``base`` check."""
    warning = base_frame_warning(bag.base_frame, request.base_frame)
    return FlangePoses(
        bag.poses,
        bag.base_frame,
        f"{len(bag.poses)} poses on {bag.pose_topic} (frame {bag.base_frame})",
        [] if warning is None else [warning],
    )


def poses_from_tf(bag: BagContents, request: PoseRequest) -> FlangePoses:
    """The flange poses of the TF chain ``base_frame`` -> ``flange_frame`` of the bag.

    Raises
    ------
    TfChainError
        When the chain cannot be built (the message lists the frames and the gap).
    BagError
        Without ``/tf`` and ``/tf_static``, or when the chain has no complete stamp.
    """
    recording = read_tf(bag.path)
    poses = recording.tree.flange_poses(
        request.base_frame, request.flange_frame, request.sync_tolerance_s
    )
    if not poses:
        raise BagError(
            f"bag {bag.path}: the TF chain {request.base_frame} -> {request.flange_frame} "
            f"exists but no stamp has all its dynamic transforms within "
            f"{request.sync_tolerance_s * 1e3:.1f} ms of each other ({recording.tree.describe()})"
            "; raise --sync-tolerance"
        )
    warnings = sorted(recording.tree.conflicts)
    if recording.skipped:
        reasons = sorted({s.reason for s in recording.skipped})
        warnings.append(
            f"{len(recording.skipped)} TF transforms were skipped: {'; '.join(reasons[:3])}"
        )
    return FlangePoses(
        poses,
        request.base_frame,
        f"{len(poses)} poses of TF {request.base_frame} -> {request.flange_frame} "
        f"({recording.dynamic_count} on {TF_TOPIC}, {recording.static_count} on "
        f"{TF_STATIC_TOPIC})",
        warnings,
    )


def poses_from_joint_states(bag: BagContents, request: PoseRequest) -> FlangePoses:
    """Forward kinematics of the bag's joint states through ``request.model``.

    Raises
    ------
    InputError
        Without a model, or when the joint states do not name the model's joints (both
        lists are given).
    BagError
        When the bag holds no JointState messages (its topics are listed).
    """
    model = request.model
    if model is None:
        raise InputError(
            "the joint_states pose source needs the robot's kinematic model: pass "
            "--kinematics ur5e, ur10e or a URDF file"
        )
    states = read_joint_states(bag.path, topic=request.joint_state_topic)
    try:
        poses = flange_poses_from_joint_states(model, states)
    except InputError as err:
        raise InputError(f"bag {bag.path}: {err}") from None
    return FlangePoses(
        poses,
        model.base_frame,
        f"{len(poses)} poses from joint states ({model.name} model, frame {model.base_frame})",
        joint_states=states,
    )


def refuse_pose_topic(source: PoseSource, pose_topic: str | None) -> None:
    """Refuse a PoseStamped topic (``--pose-topic``) when the poses come from elsewhere.

    Raises
    ------
    InputError
    """
    if source is not PoseSource.POSE and pose_topic is not None:
        raise InputError(
            f"--pose-topic names a PoseStamped topic, but the flange poses come from "
            f"--pose-source {source.value}: drop --pose-topic, or use --pose-source pose"
        )


#: One function per pose source; a new source adds its member and its function here.
POSE_SOURCES: dict[PoseSource, Callable[[BagContents, PoseRequest], FlangePoses]] = {
    PoseSource.POSE: poses_from_pose_topic,
    PoseSource.TF: poses_from_tf,
    PoseSource.JOINT_STATES: poses_from_joint_states,
}
