"""Realistic simulator of line-laser cylinder scans (pure numpy/scipy).

``simulate(scenario_from_preset("ur_scancontrol"), seed=1)`` gives profiles, the reported
flange-pose stream and the ground truth. Modules:

- :mod:`~linelaser_calib.sim.scenario`: the :class:`Scenario` knobs and their validation;
- :mod:`~linelaser_calib.sim.presets`: the named presets and random scenes;
- :mod:`~linelaser_calib.sim.scene`: cylinder and background geometry, ray casting;
- :mod:`~linelaser_calib.sim.profiler`: the laser fan, noise, spikes, dropouts, intensity;
- :mod:`~linelaser_calib.sim.poses`: sensor poses at the paper's recommended cut angles;
- :mod:`~linelaser_calib.sim.robot`: step-and-shoot and continuous motion, pose errors;
- :mod:`~linelaser_calib.sim.simulate`: the entry point and the output records.
"""

from __future__ import annotations

from linelaser_calib.sim.presets import PRESETS, random_scenario, scenario_from_preset
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import Surface
from linelaser_calib.sim.simulate import SimulatedData, SimulationTruth, simulate

__all__ = [
    "PRESETS",
    "Scenario",
    "SimulatedData",
    "SimulationTruth",
    "Surface",
    "random_scenario",
    "scenario_from_preset",
    "simulate",
]
