"""Reports of a calibration result for people: an HTML page and an MCAP file for Foxglove.

- :func:`~linelaser_calib.report.html.write_report`: a self-contained HTML page with
  matplotlib figures (matplotlib is imported only when a report is made).
- :func:`~linelaser_calib.report.viz.write_viz_mcap`: the calibrated profiles, the fitted
  target's markers and the transforms as ROS 2 messages in one MCAP file;
  :func:`~linelaser_calib.report.viz.write_cloud_mcap`: point clouds (a reconstruction).

Nothing in :mod:`linelaser_calib.core` imports this package.
"""

from __future__ import annotations

from linelaser_calib.report.errors import ReportError
from linelaser_calib.report.html import require_matplotlib, write_report
from linelaser_calib.report.viz import VIZ_TOPICS, write_cloud_mcap, write_viz_mcap

__all__ = [
    "VIZ_TOPICS",
    "ReportError",
    "require_matplotlib",
    "write_cloud_mcap",
    "write_report",
    "write_viz_mcap",
]
