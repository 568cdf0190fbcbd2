"""A column file small enough to travel from one GPU call to the next: the particles of a `colsim trim`
file (positions, velocities, angular velocities and radii, float64) with its attributes, without the
contact forces it carries to warm-start the collapse's first step (most of its bytes: an r0 = 4, a = 5
column of 20,315 spheres, 6.1 MB, travels as 1.6 MB, 81 bytes a sphere). `colsim collapse` takes it
as it takes the full file, its first step solved from no guess.

    python3 benchmarks/travelling_column.py COLUMN.nc OUT.nc
"""
from __future__ import annotations

import sys

from colsim.io.state_file import read_state, write_state


def write_travelling_column(source, target) -> None:
    """The particles and attributes of the column file `source` into `target`."""
    state, dataset = read_state(source)
    write_state(target, state, dataset.attrs)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    write_travelling_column(sys.argv[1], sys.argv[2])
