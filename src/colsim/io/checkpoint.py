"""The checkpoints of a collapse and of a packing: numpy .npz archives of plain arrays, read with
allow_pickle=False: loading one can run no code, and its fingerprint (the run's inputs and
settings) is compared before anything else in it is used. Written to a temporary name, then renamed.

A collapse's holds the state, the frames so far, the steps' diagnostics, and the warm start and
margin carried to the next step; a packing's, the state, the steps' diagnostics and what its filling
loop carries (:func:`save_packing_checkpoint`).
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..engine.records import TEXT_DIAGNOSTICS, Carry, StepDiagnostics
from ..engine.state import ParticleState
from ..engine.warm_start import WarmStart
from .netcdf import atomic_path

log = logging.getLogger(__name__)

STATE_FIELDS = ("position", "velocity", "angular_velocity")
WARM_FIELDS = ("i", "j", "family", "force", "rolling")


def save_checkpoint(path, fingerprint, state, frames, diagnostics, carry, elapsed, cpu=float("nan")):
    """A collapse after its last step: `elapsed` and `cpu`, the wall and CPU seconds spent so far."""
    arrays = _common_arrays(fingerprint, state, carry.warm_start, carry.margin, elapsed, cpu)
    arrays["frame_step"] = np.array([k for k, _ in frames], dtype=np.int64)
    arrays["frame_time"] = np.array([f.time for _, f in frames])
    for name in STATE_FIELDS:
        arrays[f"frame_{name}"] = np.stack([getattr(f, name) for _, f in frames])
    arrays.update(_diagnostic_arrays(diagnostics))
    _write(path, arrays)


def load_checkpoint(path, fingerprint):
    """The saved run ({state, frames, diagnostics, carry, elapsed, cpu}) if `path` holds a checkpoint of
    this fingerprint; None (with a warning) for another run's or an unreadable file."""
    return _read(path, fingerprint, _restore)


def save_packing_checkpoint(path, fingerprint, state, warm, margin, loop: dict, elapsed, cpu=float("nan"),
                            diagnostics=()):
    """A packing in the middle of a cloud: `state` (all spheres placed), the forces by pair `warm`
    (WarmStart in the numbering of `state`, or None) and the detection `margin` (None: the base
    one) that the next step starts from, and `loop`: the filling loop's arrays and numbers
    (name -> array, bool, int, float or str); `elapsed` and `cpu`: the wall and CPU seconds spent so
    far; `diagnostics`: the StepDiagnostics of the steps so far."""
    arrays = _common_arrays(fingerprint, state, warm, margin, elapsed, cpu)
    arrays.update(_diagnostic_arrays(diagnostics))
    for name, value in loop.items():
        arrays[f"loop_{name}"] = np.asarray(value)
    _write(path, arrays)


def load_packing_checkpoint(path, fingerprint):
    """The saved packing ({state, warm, margin, loop, diagnostics, elapsed, cpu}) if `path` holds a
    packing checkpoint of this fingerprint; None (with a warning) otherwise. loop's values come back
    as numpy arrays (0-d for numbers and text); diagnostics is empty for a checkpoint written before
    packings kept them."""
    def restore(arrays):
        state, warm, margin = _common_of(arrays)
        loop = {name[len("loop_"):]: value for name, value in arrays.items() if name.startswith("loop_")}
        diagnostics = _diagnostics_of(arrays) if "diagnostic_step" in arrays else []
        return {"state": state, "warm": warm, "margin": margin, "loop": loop, "diagnostics": diagnostics,
                **_spent(arrays)}
    return _read(path, fingerprint, restore)


def checkpoint_summary(path) -> dict:
    """What a checkpoint says of its run, without restoring it or checking whose it is: {stage:
    "collapse" or "packing", spheres, step (the last one done), time (simulated), kinetic_energy
    (translational, of the last step), seconds_per_step (wall, mean over the last 10 steps), elapsed
    and cpu (wall and CPU seconds so far)}; NaN where an older checkpoint lacks the step record.
    Reads only the small arrays."""
    with np.load(path, allow_pickle=False) as archive:
        names = set(archive.files)
        stage = "collapse" if "frame_step" in names else "packing"
        spheres = int(archive["radius"].shape[0])
        time = float(archive["state_time"])
        spent = _spent(archive)
        if "diagnostic_step" in names and archive["diagnostic_step"].size:
            step = int(archive["diagnostic_step"][-1])
            energy = float(archive["diagnostic_kinetic_energy"][-1])
            per_step = float(np.mean(archive["diagnostic_wall_time"][-10:]))
        else:
            step, energy, per_step = -1, float("nan"), float("nan")
    return {"stage": stage, "spheres": spheres, "step": step, "time": time, "kinetic_energy": energy,
            "seconds_per_step": per_step, **spent}


def _write(path, arrays: dict) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez(handle, **arrays)


def _read(path, fingerprint, restore):
    """restore(arrays) of the checkpoint at `path` if its fingerprint is `fingerprint`, else None."""
    if path is None or not Path(path).is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as archive:
            if str(archive["fingerprint"]) != fingerprint:
                log.warning("ignoring checkpoint %s: it belongs to other inputs or settings", path)
                return None
            return restore(dict(archive))
    except Exception as error:  # a checkpoint from another version, a damaged or foreign file
        log.warning("ignoring unreadable checkpoint %s (%s)", path, error)
        return None


def _restore(arrays) -> dict:
    """The run saved by :func:`save_checkpoint` from its arrays."""
    state, warm, margin = _common_of(arrays)
    frames = [(int(k), ParticleState(*(arrays[f"frame_{name}"][n] for name in STATE_FIELDS), state.radius,
                                     state.density, float(arrays["frame_time"][n])))
              for n, k in enumerate(arrays["frame_step"])]
    return {"state": state, "frames": frames, "diagnostics": _diagnostics_of(arrays), "carry": Carry(warm, margin),
            **_spent(arrays)}


def _diagnostic_arrays(diagnostics) -> dict:
    """diagnostic_<field>: one array a field of StepDiagnostics, over the steps."""
    return {f"diagnostic_{name}": np.array([getattr(d, name) for d in diagnostics],
                                           dtype=str if name in TEXT_DIAGNOSTICS else None)
            for name in StepDiagnostics.__dataclass_fields__}


def _diagnostics_of(arrays) -> list:
    """The StepDiagnostics saved by :func:`_diagnostic_arrays`."""
    fields = StepDiagnostics.__dataclass_fields__
    columns = {name: arrays[f"diagnostic_{name}"].tolist() for name in fields}
    return [StepDiagnostics(**{name: columns[name][k] for name in fields}) for k in range(len(columns["step"]))]


def _common_arrays(fingerprint, state, warm, margin, elapsed, cpu) -> dict:
    """What both checkpoints hold: the fingerprint, the state, the forces by pair (if any) and the
    detection margin (NaN for None) the next step starts from, the wall and CPU seconds spent."""
    arrays = {"fingerprint": np.array(fingerprint), "elapsed": np.array(elapsed), "cpu": np.array(cpu),
              "radius": state.radius,
              "density": np.array(state.density), "state_time": np.array(state.time),
              "margin": np.array(np.nan if margin is None else margin)}
    for name in STATE_FIELDS:
        arrays[f"state_{name}"] = getattr(state, name)
    if warm is not None:
        for name in WARM_FIELDS:
            arrays[f"warm_{name}"] = getattr(warm, name)
    return arrays


def _spent(arrays) -> dict:
    """{elapsed, cpu}: the wall and CPU seconds a checkpoint's run had taken (cpu NaN for a checkpoint
    written before it was saved)."""
    return {"elapsed": float(arrays["elapsed"]), "cpu": float(arrays["cpu"]) if "cpu" in arrays else float("nan")}


def _common_of(arrays) -> tuple:
    """(state, warm start or None, margin or None) from :func:`_common_arrays`' arrays."""
    state = ParticleState(*(arrays[f"state_{name}"] for name in STATE_FIELDS), arrays["radius"],
                          float(arrays["density"]), float(arrays["state_time"]))
    warm = WarmStart(*(arrays[f"warm_{name}"] for name in WARM_FIELDS)) if "warm_i" in arrays else None
    margin = float(arrays["margin"])
    return state, warm, None if np.isnan(margin) else margin
