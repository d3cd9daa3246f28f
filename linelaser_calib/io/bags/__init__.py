"""rosbag2 (MCAP) recordings of profiles and flange poses: write, read, summarise, append.

A recording holds ``sensor_msgs/msg/PointCloud2`` profiles in the sensor frame and
``geometry_msgs/msg/PoseStamped`` flange poses in the base frame. Bags are written with
rosbags as rosbag2 version 9 MCAP directories (``metadata.yaml`` + ``<name>.mcap``), with each
message logged at its header stamp. Reading uses rosbags' rosbag2 ``Reader`` (MCAP or
SQLite 3 storage); in an indexed MCAP file the two topics' messages are read through its
chunk and message indexes instead (:mod:`.indexed`: a chunk's messages of a topic in one
buffer, nothing per message). The profiles and flange poses are decoded by hand-written CDR
readers (:mod:`.cdr`), anything else, or what they cannot read, by rosbags' typestores: the
definitions of PointCloud2 and PoseStamped (and of Header, Time, PointField, Pose) are the
same in every ROS 2 distribution, so this decodes bags recorded with any of them.

Durability. rosbags buffers messages in memory (MCAP chunks of about 1 MiB) and writes the
chunk index, the summary and ``metadata.yaml`` only on close; its reader needs all of them.
So a rosbag2 bag is readable only once closed. :func:`write_bag` therefore writes into a
hidden temporary directory and renames it into place when complete: a crash leaves no
half-written bag under the requested name. :class:`SessionBagWriter`, for live collection,
appends the samples (each a profile and its flange pose) to one MCAP file of unchunked
records, flushed and fsynced on request, which this module reads record by record up to a
torn tail; a crash loses only what was not flushed yet. :func:`read_bag` reads a session
directory like a single bag (also a session of one bag per sample, written by earlier
versions).

Topics are auto-detected by type when exactly one topic of each type holds messages.
Every user-caused failure (missing, empty, truncated or corrupt bag, missing or ambiguous
topics, wrong types) raises :class:`~linelaser_calib.io.errors.BagError` saying what to do;
a single malformed message is skipped and reported in :attr:`BagContents.skipped`.

One module per job: :mod:`.records` (names and records), :mod:`.cdr` (typestores, the
batch PoseStamped decoder and the PointCloud2 decoder), :mod:`.indexed` (an MCAP file read
through its indexes), :mod:`.write`, :mod:`.session` (the collector's format), :mod:`.read`
and :mod:`.info`.
"""

from __future__ import annotations

from linelaser_calib.io.bags.cdr import decode_message, reading_store
from linelaser_calib.io.bags.info import BagInfo, PointCount, bag_info, format_bag_info
from linelaser_calib.io.bags.read import (
    bag_parts,
    open_part,
    raw_messages,
    read_bag,
    read_joint_states,
    read_profile_intensities,
)
from linelaser_calib.io.bags.records import (
    JOINT_STATE_TOPIC,
    JOINT_STATE_TYPE,
    POSE_TYPE,
    PROFILE_TYPE,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    TF_TYPE,
    BagContents,
    Progress,
    SkippedMessage,
    TopicSummary,
)
from linelaser_calib.io.bags.session import (
    MCAP_MAGIC,
    SESSION_FILE,
    SESSION_MARKER,
    SessionBagWriter,
)
from linelaser_calib.io.bags.write import write_bag

__all__ = [
    "JOINT_STATE_TOPIC",
    "JOINT_STATE_TYPE",
    "MCAP_MAGIC",
    "POSE_TYPE",
    "PROFILE_TYPE",
    "SESSION_FILE",
    "SESSION_MARKER",
    "TF_STATIC_TOPIC",
    "TF_TOPIC",
    "TF_TYPE",
    "BagContents",
    "BagInfo",
    "PointCount",
    "Progress",
    "SessionBagWriter",
    "SkippedMessage",
    "TopicSummary",
    "bag_info",
    "bag_parts",
    "decode_message",
    "format_bag_info",
    "open_part",
    "raw_messages",
    "read_bag",
    "read_joint_states",
    "read_profile_intensities",
    "reading_store",
    "write_bag",
]
