"""File I/O: rosbag2 recordings (rosbags) and result/truth YAML files.

Kept out of :mod:`linelaser_calib.core`, which never imports rosbags or yaml.
"""

from __future__ import annotations

from linelaser_calib.io.bags import (
    BagContents,
    BagInfo,
    SessionBagWriter,
    SkippedMessage,
    TopicSummary,
    bag_info,
    format_bag_info,
    read_bag,
    write_bag,
)
from linelaser_calib.io.errors import BagError, ResultFileError
from linelaser_calib.io.results import (
    Truth,
    read_result_yaml,
    read_truth_yaml,
    result_to_dict,
    truth_beside,
    write_result_yaml,
    write_truth_yaml,
)

__all__ = [
    "BagContents",
    "BagError",
    "BagInfo",
    "ResultFileError",
    "SessionBagWriter",
    "SkippedMessage",
    "TopicSummary",
    "Truth",
    "bag_info",
    "format_bag_info",
    "read_bag",
    "read_result_yaml",
    "read_truth_yaml",
    "result_to_dict",
    "truth_beside",
    "write_bag",
    "write_result_yaml",
    "write_truth_yaml",
]
