"""Per-step diagnostics (:class:`colsim.engine.records.StepDiagnostics`) as netCDF variables over a
`step` dimension, with units and long names: a collapse's trajectory and a packing's file hold them."""
from __future__ import annotations

import numpy as np

from ..engine.records import TEXT_DIAGNOSTICS, StepDiagnostics

DIAGNOSTIC_FIELDS = [f for f in StepDiagnostics.__dataclass_fields__ if f not in TEXT_DIAGNOSTICS]

#: long names of per-step diagnostics: the wall-clock times (s) apart from the simulation's time
STEP_LONG_NAMES = {"time": "simulation time at the end of the step",
                   "detection_time": "wall-clock time of the step's contact detection",
                   "assembly_time": "wall-clock time of the step's assembly",
                   "matching_time": "wall-clock time of the warm start's matching in the step",
                   "check_time": "wall-clock time of the step's overlap check",
                   "setup_time": "wall-clock time of the solver's set-up in the step",
                   "solve_time": "wall-clock time of the solver in the step",
                   "wall_time": "wall-clock time of the step"}

STEP_UNITS = {"time": "time", "largest_overlap": "length", "kinetic_energy": "mass length^2/time^2",
              "rotational_energy": "mass length^2/time^2", "detection_time": "s", "assembly_time": "s",
              "setup_time": "s", "solve_time": "s", "detection_margin": "length", "wall_time": "s",
              "matching_time": "s", "check_time": "s"}


def step_variables(diagnostics) -> dict:
    """{name: (dims, values, attrs)}: `step` (the step numbers) and step_<field> for each field of
    the steps' diagnostics (a list of StepDiagnostics)."""
    data = {"step": ("step", np.array([d.step for d in diagnostics]),
                     {"units": "1", "long_name": "step number"})}
    for name in DIAGNOSTIC_FIELDS:
        if name == "step":
            continue
        values = np.array([getattr(d, name) for d in diagnostics])
        data[f"step_{name}"] = ("step", values, {"units": STEP_UNITS.get(name, "1"),
                                                 "long_name": STEP_LONG_NAMES.get(name, name.replace("_", " ") + " per step")})
    for name, long_name in TEXT_DIAGNOSTICS.items():
        data[f"step_{name}"] = ("step", np.array([getattr(d, name) for d in diagnostics], dtype=object),
                                {"long_name": long_name})
    return data
