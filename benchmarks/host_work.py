"""The host's work in a GPU collapse step, timed on the CPU: what is left to move for "kernels at 80 %".

    python -m benchmarks host_work COLUMN [--tile R0] [--repeat 5]

A step on the GPU (the CUDA back-end) still runs some numpy on the host: detection's fixed
spheres (the pairs, the walls and every contact's arrays are made on the device) and the step's
smallest and mean diameters from the radii. The rest has left the host, and is timed here as it was
made there: the increments, 1 / mass, the predicted motion, the grid's bounds, the midpoints, the
assembly, the update, the overlap check's walls and the kinetic energy (until 2026-11-29 the host
made its own copy of the particles' arrays each step, beside the device's).

Each is timed here, best of `--repeat`, on the column (`colsim trim`) or on a column of radius R0
tiled from it (benchmarks/tiling.py). Velocities are drawn at 0.01, so that every particle moves.

Some pieces are timed both ways, as 93f3a2a's GPU step ran them and as it runs them now:
- the overlap check, with the pairs measured on the host, or measured by the GPU's detection;
- the warm start's global forces and keys, which the GPU's step now makes on the device;
- detection's joins of the pairs' arrays with the walls', which the device now makes;
- the floor's and the cylinder's contacts, which the device now makes too;
- a redo's join of its given pairs (GIVEN of them) with the pairs found, now on the device.

No GPU is needed: nothing here launches a kernel. glibc's allocator makes the figures depend on the
process's history: set MALLOC_MMAP_THRESHOLD_ and MALLOC_TRIM_THRESHOLD_ to
compare runs.
"""
from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time

import numpy as np

import record
import tiling


#: a redo's given pairs (the stepper's missed ones: 325-606 a step in r0 = 6's pour)
GIVEN = 500


def best_ms(repeat: int, call, *args) -> float:
    """The best wall time of call(*args) over `repeat` calls (ms)."""
    times = []
    for _ in range(repeat):
        begin = time.perf_counter()
        call(*args)
        times.append(time.perf_counter() - begin)
    return 1e3 * min(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", help="a column file (colsim trim)")
    parser.add_argument("--tile", type=float, metavar="R0", help="time a column of radius R0 tiled from it")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)

    from colsim import io
    from colsim.engine import contacts as detection
    from colsim.engine.cuda_contacts import _grid
    from colsim.engine.program import assemble
    from colsim.engine.state import ContactLaw, StepSettings, Walls, pair_keys
    from colsim.engine.backend import advance, predicted_displacement
    from colsim.engine.backends import make_backend
    from colsim.engine.warm_start import WarmStart

    with tempfile.TemporaryDirectory() as scratch:
        state, _ = io.read_state(tiling.column_or_tiled(args.column, args.tile, scratch))
    state.velocity[:] = np.random.default_rng(1).normal(scale=0.01, size=state.velocity.shape)
    settings = StepSettings(dt=0.001, law=ContactLaw.uniform(0.577, 0.12), walls=Walls(floor=True))
    predicted = predicted_displacement(state, settings)
    margin = 0.05 * 2.0 * float(state.radius.min())
    pairs = detection.swept_pairs(state, predicted, margin, settings.detection_slack)
    frames = detection.pair_frames(state, *pairs, None, 0.01)
    r = args.repeat

    def detect_given_pairs(renormal=None):   # detect on the CPU, with the swept pairs and their frames given
        found_pairs, found_frames = detection.swept_pairs, detection.pair_frames
        detection.swept_pairs = lambda *a, **k: pairs
        detection.pair_frames = lambda s, i, j, normal, most: frames if normal is None else found_frames(
            s, i, j, normal, most)
        try:
            return detection.detect(state, settings.walls, settings.law, predicted, margin, settings.detection_slack,
                                    np.zeros(state.n), renormal, 0.01)
        finally:
            detection.swept_pairs, detection.pair_frames = found_pairs, found_frames

    given = (pairs[0][:GIVEN], pairs[1][:GIVEN], frames[0].reshape(-1, 3)[:GIVEN])   # a redo's pairs and normals

    def given_rows():   # a redo's given pairs' rows, made on the host to join on the device
        return detection.pair_rows(state, settings.law, given[0], given[1], detection.pair_frames(state, *given, 0.01))

    found = detect_given_pairs()

    cuda = make_backend("cuda")

    def detect_given_the_gpu_s():   # detect as the GPU's step runs it, the device's contacts given
        from colsim.engine import cuda_backend

        device_part = cuda_backend.swept_contacts
        cuda_backend.swept_contacts = lambda *a, **k: found
        try:
            return cuda.detect(state, settings.walls, settings.law, predicted, margin, settings.detection_slack,
                               np.zeros(state.n), None, 0.01)
        finally:
            cuda_backend.swept_contacts = device_part

    def walls_on_the_host():   # the walls' contacts as the GPU's step made them on the host before 2026-11-29
        reach = margin + (1.0 + settings.detection_slack) * detection.row_lengths(predicted)
        return detection._other_contacts(state, settings.walls, settings.law, reach, np.zeros(state.n), 0.01)

    program = assemble(state, found, settings.dt, settings.gravity)
    midpoint, reach = detection.swept_midpoints(state, predicted, margin, settings.detection_slack)
    moved = advance(state, 1e-9 * np.ones(6 * state.n), settings.dt)
    forces = np.random.default_rng(2).uniform(size=(found.m, 5))
    measured = dataclasses.replace(found, largest_pair_overlap=0.0)   # as the GPU's detection measures it

    def host_bounds(midpoint, reach):   # the grid's bounds as the host made them before 2026-11-29
        return _grid(np.array([midpoint[:, d].min() for d in range(3)]),
                     np.array([midpoint[:, d].max() for d in range(3)]), reach, state.n)

    def step_radii():   # what a step still reads of the particles on the host
        return 2.0 * float(np.min(state.radius)), 2.0 * float(np.mean(state.radius))

    def keys():
        found.__dict__.pop("keys", None)
        return found.keys

    print(f"{args.column if not args.tile else f'r0 = {args.tile:g} tiled from {args.column}'}: "
          f"{state.n} spheres, {found.m} contacts")
    table = record.table(["phase (host)", "ms", "on the GPU's step"])
    rows = [
        ("detection's walls, joins, levers, coefficients (every array joined on the host)",
         best_ms(r, detect_given_pairs), "before"),
        ("detection's walls (every array made on the device, the walls' on the host)",
         best_ms(r, walls_on_the_host), "before"),
        ("detection's host work (the walls' arrays made on the device too)", best_ms(r, detect_given_the_gpu_s),
         "now"),
        (f"a redo's join of {GIVEN} given pairs (every array joined on the host)",
         best_ms(r, detect_given_pairs, given), "before"),
        (f"a redo's {GIVEN} given pairs' rows (joined on the device)", best_ms(r, given_rows), "now"),
        ("the grid's bounds", best_ms(r, host_bounds, midpoint, reach), "on the device (before 2026-11-29: host)"),
        ("midpoints", best_ms(r, detection.swept_midpoints, state, predicted, margin, settings.detection_slack),
         "on the device (before 2026-11-29: also host)"),
        ("predicted motion", best_ms(r, predicted_displacement, state, settings),
         "on the device (before 2026-11-29: also host, once a step)"),
        ("the assembly", best_ms(r, assemble, state, found, settings.dt, settings.gravity),
         "on the device (before 2026-11-29: also host)"),
        ("the step's radii: its smallest and mean diameters", best_ms(r, step_radii), "on the host"),
        ("APGD's inverse masses 1 / mass", best_ms(r, lambda: 1.0 / program.mass), "on the device (before 3b1e40b: host)"),
        ("increments (fbar + B' lam) / mass", best_ms(r, lambda: (program.fbar + program.fbar) / program.mass),
         "on the device (before 047c585: host)"),
        ("the update", best_ms(r, advance, state, 1e-9 * np.ones(6 * state.n), settings.dt),
         "on the device (before 2026-11-29: also host)"),
        ("the overlap check, pairs measured on the host",
         best_ms(r, cuda.overlaps, moved, settings.walls, 1e-4, found), "before"),
        ("the overlap check, pairs measured by detection",
         best_ms(r, cuda.overlaps, moved, settings.walls, 1e-4, measured),
         "before 2026-11-29 (now the walls' on the device too)"),
        ("the kinetic energy", best_ms(r, moved.kinetic_energy), "on the device (before 2026-11-29: host)"),
        ("the warm start's global forces", best_ms(r, WarmStart.from_step, found, forces), "on the device"),
        ("the warm start's keys, stored and new",
         best_ms(r, lambda: (pair_keys(found.i, found.j, found.family), pair_keys(found.i, found.j, found.family))),
         "before"),
        ("the new contacts' keys, once", best_ms(r, keys), "before (now on the device)"),
    ]
    for phase, ms, where in rows:
        table.row(phase, f"{ms:.1f}", where, data={"phase": phase, "ms": ms, "gpu_step": where,
                                                   "spheres": state.n, "contacts": found.m})


if __name__ == "__main__":
    record.run("host_work", main)
