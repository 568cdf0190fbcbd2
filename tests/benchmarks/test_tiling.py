"""benchmarks/tiling.py: a column tiled from a smaller one, for timing the r0 = 13 steps. It must be a
column the collapse accepts: inside its cylinder and below h0, no overlap across the seams beyond the
source's own, and its warm start's pairs among its spheres."""
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from colsim import io
from colsim.engine.state import FLOOR, PARTICLE, ParticleState
from colsim.engine.warm_start import WarmStart

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from tiling import tiled_column  # noqa: E402

RADIUS = 0.2


def _lattice_column(path, r0=2.0, aspect_ratio=2.0):
    """Spheres of radius 0.2 touching on a simple cubic lattice inside a cylinder of radius r0, below
    h0 = a r0, with a unit force on each vertical pair and on each floor contact."""
    step = 2 * RADIUS
    axis = np.arange(-r0, r0, step) + RADIUS
    x, y, z = np.meshgrid(axis, axis, np.arange(RADIUS, aspect_ratio * r0 - RADIUS + 1e-9, step), indexing="ij")
    position = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    position = position[np.hypot(position[:, 0], position[:, 1]) + RADIUS <= r0]
    n = len(position)
    state = ParticleState(position, np.zeros((n, 3)), np.zeros((n, 3)), np.full(n, RADIUS), 1.0, 0.0)
    pairs = cKDTree(position).query_pairs(step + 1e-9, output_type="ndarray")
    vertical = pairs[np.isclose(np.abs(position[pairs[:, 1], 2] - position[pairs[:, 0], 2]), step)]
    floor = np.flatnonzero(np.isclose(position[:, 2], RADIUS))
    i = np.concatenate([vertical[:, 0], floor])
    j = np.concatenate([vertical[:, 1], np.full(len(floor), -1)])
    family = np.concatenate([np.full(len(vertical), PARTICLE), np.full(len(floor), FLOOR)])
    force = np.tile([1.0, 0.0, 0.0], (len(i), 1))
    attrs = {"colsim_kind": "particle-state", "r0": r0, "h0": aspect_ratio * r0, "aspect_ratio": aspect_ratio}
    io.write_state(path, state, attrs, io.contact_force_variables(WarmStart(i, j, family, force, 0 * force)))
    return state


def test_a_tiled_column_fills_its_cylinder_without_overlaps(tmp_path):
    source = _lattice_column(tmp_path / "small.nc")
    n = tiled_column(str(tmp_path / "small.nc"), 5.0, str(tmp_path / "big.nc"))
    state, dataset = io.read_state(tmp_path / "big.nc")
    assert n == state.n > 3 * source.n
    assert dataset.attrs["r0"] == 5.0 and dataset.attrs["h0"] == 10.0 and "not a pour" in dataset.attrs["title"]
    assert np.all(np.hypot(state.position[:, 0], state.position[:, 1]) + state.radius <= 5.0 + 1e-12)
    assert np.all(state.position[:, 2] + state.radius <= 10.0 + 1e-12)
    assert np.all(state.velocity == 0.0) and np.all(state.angular_velocity == 0.0)
    pairs = cKDTree(state.position).query_pairs(2 * RADIUS, output_type="ndarray")
    distance = np.linalg.norm(state.position[pairs[:, 0]] - state.position[pairs[:, 1]], axis=1)
    # the box (2.03 wide) is not a whole number of lattice spacings (0.4): the copies overlap at each seam
    # until one of each such pair goes, and then nothing overlaps (the lattice itself only touches)
    assert distance.min() >= 2 * RADIUS * (1 - 1e-12)
    warm = io.contact_forces_of(dataset)
    particle, floor = warm.family == PARTICLE, warm.family == FLOOR
    assert particle.sum() > 0 and floor.sum() > 0
    gaps = np.linalg.norm(state.position[warm.i[particle]] - state.position[warm.j[particle]], axis=1) - 2 * RADIUS
    np.testing.assert_allclose(gaps, 0.0, atol=1e-12)        # every carried pair is a touching pair
    np.testing.assert_allclose(state.position[warm.i[floor], 2], RADIUS)   # floor forces at the floor only
