"""The step's back-end on one NVIDIA GPU (numba.cuda): the CPU's back-end, with what runs there
overridden (as LAMMPS's /gpu styles subclass their CPU styles).

The particles' arrays, the swept pairs and their frames, the floor's and the cylinder's rows, the
program's masses and free forces, APGD's iteration, the warm start and the particles' update stay on
the device from step to step (:mod:`colsim.engine.cuda_state`, :mod:`colsim.engine.cuda_contacts`,
:mod:`colsim.engine.cuda_warm_start`, :mod:`colsim.engine.cuda_apgd`); a host array is copied from
there only when read. What the GPU does not make is made on the host, as the CPU's back-end makes it:
the fixed spheres' contacts, a redo's given pairs and cylinder margin, a step with fewer than two
particles. The arithmetic is the CPU's (to rounding: a GPU fuses some multiply-adds).
"""
from __future__ import annotations

import numpy as np

from . import contacts as contact_detection
from .backend import CpuBackend, advance
from .cuda_apgd import STORAGES, CudaIteration
from .cuda_contacts import join_given_pairs, swept_contacts, swept_pairs_on_device
from .cuda_state import advance_on_device, measured_on_device, predicted_on_device, program_on_device
from .cuda_warm_start import carried_on_device, match_on_device
from .state import Walls
from .warm_start import WarmStart


class CudaBackend(CpuBackend):
    """The step on one GPU (see the module docstring)."""

    name = "cuda"
    apgd_kernel = "cuda"
    storages = STORAGES

    def predicted(self, state, settings):
        if not state.n:
            return super().predicted(state, settings)
        return predicted_on_device(state, settings.dt, settings.gravity)

    def detect(self, state, walls, law, predicted, margin, slack=0.5, cylinder_margin=0.0, renormal=None,
               most_recovered=np.inf, kept=0.0):
        """The swept pairs, their frames and, where no cylinder margin is asked for (a first attempt's),
        the floor's, the cylinder's and the planes' rows made on the device; the fixed spheres' rows and a redo's given
        pairs made on the host and joined there (:func:`colsim.engine.cuda_contacts.join_given_pairs`).
        Fewer than two particles, or no contact: the host's detection."""
        has_walls = walls.floor or walls.cylinder_radius is not None or bool(walls.planes)
        on_device = walls if has_walls and not np.any(cylinder_margin) else None
        host_walls = Walls(floor=False, fixed=walls.fixed) if on_device else walls
        others = contact_detection.other_rows(state, host_walls, law, predicted, margin, slack, cylinder_margin,
                                              most_recovered, kept)
        found = swept_contacts(state, predicted, margin, slack, most_recovered, others, law, on_device, kept)
        given = contact_detection.given_rows(state, law, renormal, most_recovered, kept)
        if found is None:
            found = super().detect(state, walls, law, predicted, margin, slack, cylinder_margin, renormal,
                                   most_recovered, kept)
            if given is None:   # nothing kept on the device: no pair overlaps
                found.largest_pair_overlap = -np.inf
            return found
        if given is None or not len(given["i"]):
            return found
        return join_given_pairs(found, given, state.n, law.rolling_lever)

    def assemble(self, state, found, dt, gravity):
        if not state.n:
            return super().assemble(state, found, dt, gravity)
        return program_on_device(state, found, dt, gravity)

    def carried(self, found, forces):
        if not found.m:
            return super().carried(found, forces)
        return carried_on_device(found, forces)

    def matched(self, warm_start: WarmStart, found):
        return match_on_device(warm_start, found)

    def advance(self, state, u, dt):
        if not state.n or isinstance(u, np.ndarray):   # a solve on the host's: the next step copies it
            return advance(state, u, dt)
        return advance_on_device(state, u, dt)

    def overlaps(self, state, walls, tolerance, detected=None):
        """The pairs' overlaps from `detected`, or the GPU's pairs at rest with no margin; a state made
        on the device has the floor's and the cylinder's largest overlaps measured there, and only
        where an overlap exceeds the tolerance (a redo, which needs each particle's) are its positions
        copied to the host and measured there; with plane walls (a channel) or fixed spheres they are
        measured on the host."""
        if detected is not None:
            largest_pair, pairs = contact_detection.detected_overlaps(detected, state, tolerance)
        else:
            pi, pj = swept_pairs_on_device(state, np.zeros_like(state.position), 0.0, 0.0)
            largest_pair, pairs = contact_detection.pair_overlaps(state, pi, pj, state.position[pj] - state.position[pi],
                                                                  tolerance)
        extents = measured_on_device(state) if (walls.fixed is None or walls.fixed.n == 0) and not walls.planes else None
        if extents is not None:
            largest_floor = max(0.0, extents[2]) if walls.floor else 0.0
            largest_cylinder = (max(0.0, extents[3] - walls.cylinder_radius) if walls.cylinder_radius is not None
                                else 0.0)
            if max(largest_pair, largest_floor, largest_cylinder) <= tolerance:   # no redo: no (n,) array
                return contact_detection.Overlaps(pairs, max(0.0, largest_pair), largest_floor, None, 0.0,
                                                  largest_cylinder)
        return contact_detection.wall_overlaps(state, walls, largest_pair, pairs)

    def apgd_iteration(self, program, warm_start, precondition, lip_decay, storage):
        return CudaIteration.of_program(program, warm_start, precondition, lip_decay, storage)
