"""A collapse's trajectory file (netCDF, kind collapse-trajectory): frames over `time` (positions,
velocities, angular velocities), the per-step diagnostics over `step`, and the run's settings as
attributes."""
from __future__ import annotations

import numpy as np
import xarray as xr

from .netcdf import AT_REST_FLAGS, at_rest_variable, run_coordinates
from .state_file import component_coordinate
from .steps import step_variables


def trajectory_dataset(run, h0: float, r0: float, settings, attrs: dict) -> xr.Dataset:
    """An xarray Dataset of the run: frames over `time`, diagnostics over `step`.

    run: a collapse's run (colsim.stages.collapse.CollapseRun: initial, frames, diagnostics, ...);
    settings: its CollapseSettings; h0, r0: the column's height and radius (length). The file
    format takes them as they come and imports nothing of the stage."""
    steps = np.array([k for k, _ in run.frames])
    frames = [s for _, s in run.frames]
    t_scale = np.sqrt(h0 / settings.gravity)
    data = {
        "position": (("time", "particle", "xyz"), np.stack([s.position for s in frames]),
                     {"units": "length", "long_name": "particle centre position"}),
        "velocity": (("time", "particle", "xyz"), np.stack([s.velocity for s in frames]),
                     {"units": "length/time", "long_name": "particle velocity"}),
        "angular_velocity": (("time", "particle", "xyz"), np.stack([s.angular_velocity for s in frames]),
                             {"units": "rad/time", "long_name": "particle angular velocity"}),
        "radius": ("particle", run.initial.radius, {"units": "length", "long_name": "particle radius"}),
        "initial_height": ("particle", run.initial.position[:, 2],
                           {"units": "length", "long_name": "height of the particle centre at release"}),
        "frame_step": ("time", steps, {"units": "1", "long_name": "step number of the frame"}),
        "at_rest": at_rest_variable((), AT_REST_FLAGS["not_checked"] if run.at_rest is None else int(run.at_rest)),
    }
    per_step = step_variables(run.diagnostics)
    step = per_step.pop("step")
    data.update(per_step)
    coords = {"time": ("time", np.array([s.time for s in frames]), {"units": "time", "long_name": "time"}),
              "scaled_time": ("time", np.array([s.time for s in frames]) / t_scale,
                              {"units": "1", "long_name": "time over sqrt(h0/g)"}),
              "step": step,
              **component_coordinate()}
    dataset = xr.Dataset(data, coords=coords, attrs=dict(attrs))
    dataset.attrs.update({"h0": h0, "r0": r0, "aspect_ratio": h0 / r0, "mu": settings.mu,
                          "mu_r": settings.mu_r, "friction_law": settings.friction_law,
                          "rolling_lever": settings.rolling_lever,
                          "dt": settings.time_step(h0),
                          "duration": settings.scaled_time(len(run.diagnostics)),
                          "n_steps": len(run.diagnostics),
                          "wall_time": run.wall_time, "cpu_time": run.cpu_time,
                          "density": float(run.initial.density)})
    if settings.friction_law == "coulomb":   # the fixed point's stopping rule, mean diameters
        dataset.attrs["friction_tolerance"] = settings.friction_tolerance
    if settings.max_duration is not None:   # the run went on towards rest: how far (whether: at_rest)
        dataset.attrs.update({"max_duration": settings.max_duration, "rest_window": settings.rest_window,
                              "rest_tolerance": settings.rest_tolerance, "rest_energy": settings.rest_energy})
    return dataset.assign_coords(run_coordinates(dataset.attrs))
