"""A large column for timing, tiled from a poured one: the first steps of an r0 = 13 column (about
700,000 spheres) without pouring it, which takes hours.

:func:`tiled_column` cuts the largest square box of spheres that stays clear of the source column's
wall and top (so no wall-ordered layer and no trimmed surface), repeats it side by side and on top of
itself, keeps the copies inside a cylinder of the new r0 and below h0 = a r0 (the source's a), and
drops one sphere of each pair of copies that overlap across a seam (the source's own pairs keep
the overlaps of its packing, within the stepper's tolerance). Velocities are zero; the contact forces of
the source's pairs inside the box (and its floor contacts, in the bottom layer of boxes) go to every
copy, as a warm start. It is a benchmark's input, labelled so in its attributes, not a packing: its
seams are looser than a pour, and its lower boxes carry the weight of a box, not of the column above.
"""
from __future__ import annotations

import math

import numpy as np


def column_or_tiled(column: str, r0: float | None, folder) -> str:
    """`column`, or (r0 given) a column of radius r0 tiled from it, written in `folder`."""
    if r0 is None:
        return column
    from pathlib import Path

    tiled = str(Path(folder) / "tiled.nc")
    tiled_column(column, r0, tiled)
    return tiled


def tiled_column(source: str, r0: float, output: str) -> int:
    """Write a column of radius r0 (length), tiled from the column file `source` (`colsim trim`), to
    `output`; returns its number of spheres."""
    from scipy.spatial import cKDTree

    from colsim import io
    from colsim.engine.state import FLOOR, PARTICLE, ParticleState
    from colsim.engine.warm_start import WarmStart

    state, dataset = io.read_state(source)
    warm = io.contact_forces_of(dataset)
    attrs = dict(dataset.attrs)
    biggest = 2.0 * float(state.radius.max())
    half = float(attrs["r0"]) / math.sqrt(2.0) - biggest       # the square inside the wall's ordered layer
    top = float(attrs["h0"]) - biggest
    x, y, z = state.position.T
    in_box = np.flatnonzero((np.abs(x) < half) & (np.abs(y) < half) & (z < top))
    width, h0 = 2.0 * half, float(attrs["aspect_ratio"]) * r0
    across, up = math.ceil((r0 + half) / width), math.ceil(h0 / top)
    offsets = [(kx * width, ky * width, kz * top) for kz in range(up)
               for kx in range(-across, across + 1) for ky in range(-across, across + 1)]
    position = np.concatenate([state.position[in_box] + offset for offset in offsets])
    radius = np.tile(state.radius[in_box], len(offsets))
    inside = (np.hypot(position[:, 0], position[:, 1]) + radius <= r0) & (position[:, 2] + radius <= h0)
    pairs = cKDTree(position[inside]).query_pairs(biggest, output_type="ndarray")
    kept_index = np.flatnonzero(inside)
    first, second = kept_index[pairs[:, 0]], kept_index[pairs[:, 1]]
    copies = len(in_box)
    across_seam = first // copies != second // copies   # the source's own pairs are its packing's
    overlapping = across_seam & (np.linalg.norm(position[first] - position[second], axis=1)
                                 < radius[first] + radius[second])
    inside[second[overlapping]] = False
    new_index = np.full(len(position), -1)
    new_index[inside] = np.arange(np.count_nonzero(inside))

    box_index = np.full(state.n, -1)
    box_index[in_box] = np.arange(len(in_box))
    forces = []
    if warm is not None:
        particle = (warm.family == PARTICLE) & (box_index[warm.i] >= 0) & (box_index[warm.j.clip(0)] >= 0)
        floor = (warm.family == FLOOR) & (box_index[warm.i] >= 0)
        for k, (_, _, dz) in enumerate(offsets):
            for chosen, walls in ((particle, False), (floor & (dz == 0.0), True)):
                i = new_index[box_index[warm.i[chosen]] + k * copies]
                j = np.full(len(i), -1) if walls else new_index[box_index[warm.j[chosen]] + k * copies]
                keep = (i >= 0) & (walls | (j >= 0))
                forces.append((i[keep], j[keep], warm.family[chosen][keep], warm.force[chosen][keep],
                               warm.rolling[chosen][keep]))
    n = int(np.count_nonzero(inside))
    tiled = ParticleState(position[inside], np.zeros((n, 3)), np.zeros((n, 3)), radius[inside],
                          state.density, 0.0)
    extra = None
    if forces:
        i, j, family, force, rolling = (np.concatenate(parts) for parts in zip(*forces))
        extra = io.contact_force_variables(WarmStart(i, j, family, force, rolling))
    for source_only in ("solid_fraction", "packing_wall_time", "packing_cpu_time"):
        attrs.pop(source_only, None)
    attrs.update(title=f"column tiled from {source} for timing (benchmarks/tiling.py): not a pour",
                 r0=float(r0), h0=h0, tiled_from=str(source), tile_box=f"{width:.4f} x {width:.4f} x {top:.4f}")
    io.write_state(output, tiled, attrs, extra)
    return n
