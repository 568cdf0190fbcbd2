"""Shared fixtures of the engine tests: a small packing poured and settled by the engine itself.

The packing is made once per session (about 10 s on 2 cores): 200 spheres with radii uniform in
[0.125, 0.25] placed by the pack stage's generator (colsim.stages.pack.starting_cloud: a cubic
lattice of spacing 0.52, each sphere at random in its cell) inside a cylinder of radius 1.5, poured
with mu = mu_r = 0 and dt = 0.02 for 150 steps, then locked by the collapse's friction
(mu = 0.577, mu_r = 0.12, cylinder still on) until its largest translational speed is below
1e-4 sqrt(g d) (d the mean diameter). The last movers are single wedged spheres whose sinking decays
by a few % a step (the associated law makes their sliding contacts dilate), so a stricter bound
costs many steps. Spin about a contact normal is not resisted (the paper's
r.n = 0), so a few spheres keep spinning slowly; the criteria are on translation.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

# the CUDA kernels' tests run on numba's CUDA simulator unless told otherwise (NUMBA_ENABLE_CUDASIM=0
# on a machine with a GPU); set before numba is imported, which reads it then
os.environ.setdefault("NUMBA_ENABLE_CUDASIM", "1")
from dataclasses import dataclass, replace

import numpy as np
import pytest

from colsim.engine.contacts import overlaps
from colsim.solvers import ClarabelSolver
from colsim.engine.state import ContactLaw, FixedSpheres, ParticleState, StepSettings, Walls
from colsim.engine.stepper import step
from colsim.stages.pack import pack, starting_cloud
from colsim.stages.settings import PackSettings
from solver_cases import COLLAPSE, collapse_program, small_pile
from helpers import COLLAPSE_LAW, DT, G, PACKING_R0, max_speed


def _index_like_a_card() -> None:
    """Make the simulator's device arrays refuse what a card's do: an allocation of no bytes has no
    pointer on a card, and numba-cuda cannot index it ("non-empty slice into empty slice"; seen on an
    H200, 2026-11-28, where the simulator had let it pass). A zero-length view of a larger allocation
    has a pointer and stays allowed."""
    from numba.cuda.simulator.cudadrv import devicearray

    plain = devicearray.FakeCUDAArray.__getitem__

    def getitem(self, index):
        allocation = self._ary
        while isinstance(allocation.base, np.ndarray):
            allocation = allocation.base
        if allocation.nbytes == 0:
            raise RuntimeError("non-empty slice into empty slice: a card cannot index a device array of no bytes")
        return plain(self, index)

    devicearray.FakeCUDAArray.__getitem__ = getitem


if os.environ["NUMBA_ENABLE_CUDASIM"] == "1":
    import cuda_simulator

    cuda_simulator.use()   # faster, and its shared arrays made under a lock
    _index_like_a_card()
#: the processes the tests start set the simulator up the same way (simulator_site/sitecustomize.py)
os.environ["PYTHONPATH"] = os.pathsep.join(
    [str(Path(__file__).resolve().parent / "simulator_site"), *filter(None, [os.environ.get("PYTHONPATH")])])

CYLINDER_RADIUS = 1.5
N_SPHERES = 200
POUR_STEPS = 150


def energy_per_particle(state: ParticleState) -> float:
    trans, rot = state.kinetic_energy()
    return (trans + rot) / state.n


@dataclass
class Pile:
    """The session's packing: poured (frictionless) and settled (locked by friction)."""

    cloud: ParticleState
    poured: ParticleState
    settled: ParticleState
    cylinder_radius: float
    pour_overlaps: list          # largest overlap after every pour step, measured afresh (length)
    pour_redone: int             # how many pour steps were redone
    overlap_tolerance: float     # the stepper's tolerance (length)
    lock_steps: int

    @property
    def mean_diameter(self) -> float:
        return 2.0 * float(self.settled.radius.mean())

    @property
    def speed_scale(self) -> float:
        """sqrt(g d): the speed a grain reaches falling about one diameter."""
        return math.sqrt(G * self.mean_diameter)

    @property
    def weight_scale(self) -> float:
        """m g of a mean sphere (force)."""
        return float(self.settled.mass.mean() * G)


@pytest.fixture(scope="session")
def pile() -> Pile:
    cloud = starting_cloud(N_SPHERES, CYLINDER_RADIUS, seed=0)
    walls = Walls(floor=True, cylinder_radius=CYLINDER_RADIUS)
    pour = StepSettings(dt=DT, walls=walls, law=ContactLaw.uniform(0.0, 0.0))
    tolerance = pour.overlap_tolerance * 2.0 * cloud.radius.min()
    solver = ClarabelSolver()
    state, largest, redone = cloud, [], 0
    for k in range(1, POUR_STEPS + 1):
        result = step(state, pour, solver, step_number=k)
        state = result.state
        largest.append(overlaps(state, walls).largest)
        redone += result.diagnostics.redone
    poured = state
    lock = replace(pour, law=COLLAPSE_LAW)
    speed_scale = math.sqrt(G * 2.0 * state.radius.mean())
    for k in range(1, 101):
        state = step(state, lock, solver, step_number=POUR_STEPS + k).state
        if max_speed(state) < 1e-4 * speed_scale:
            break
    return Pile(cloud, poured, replace(state, time=0.0), CYLINDER_RADIUS, largest, redone,
                tolerance, k)


def made_once(name: str, tmp_path_factory, make):
    """make() once for the whole run: under pytest-xdist the workers share its result through a
    pickle beside their temporary folders, the first to need it making it while the others wait
    on a lock (a worker's session fixture is its own otherwise); in one process, make()."""
    import fcntl
    import pickle

    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return make()
    shared = tmp_path_factory.getbasetemp().parent / f"{name}.pickle"
    with open(f"{shared}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not shared.is_file():
            with open(f"{shared}.part", "wb") as stream:
                pickle.dump(make(), stream)
            os.replace(f"{shared}.part", shared)
        with open(shared, "rb") as stream:
            return pickle.load(stream)


@pytest.fixture(scope="session")
def packing(tmp_path_factory) -> ParticleState:
    """The stage tests' packing: ~450 spheres poured by the pack stage into a cylinder of radius
    1.5 (PACKING_R0), 3 high, with Clarabel (about 10 s), made once for all workers."""
    return made_once("packing", tmp_path_factory, lambda: pack(PackSettings(r0=PACKING_R0, height=3.0),
                                                               np.random.default_rng([7, 0]), ClarabelSolver()))


@pytest.fixture(scope="session")
def solver_pile() -> ParticleState:
    """The back-end tests' pile: about 90 spheres poured into a cylinder of radius 1.2
    (solver_cases.small_pile; a few seconds)."""
    return small_pile()


@pytest.fixture(scope="session")
def pile_with_every_contact(solver_pile):
    """(state, contacts, program): the back-ends' pile in its cylinder, on two fixed spheres under the
    floor's level, so that its contacts hold every kind (particle, floor, cylinder, fixed sphere);
    the operator tests on the CPU and the GPU share it."""
    fixed = FixedSpheres(np.array([[0.0, 0.0, -0.05], [0.5, 0.0, -0.05]]), np.array([0.2, 0.2]))
    settings = replace(COLLAPSE, walls=Walls(floor=True, cylinder_radius=1.2, fixed=fixed))
    program, found = collapse_program(solver_pile, settings)
    assert {0, 1, 2} <= set(found.family.tolist()) and np.any(found.j <= -2)
    return solver_pile, found, program


def pytest_collection_modifyitems(config, items):
    """The workflow's tests first (each runs Snakemake: tests/workflow/test_workflow.py is the
    longest file): under pytest-xdist, which hands out whole files in this order, the workers then
    end together instead of one running the longest file alone at the end."""
    items.sort(key=lambda item: not item.nodeid.startswith("tests/workflow/"))
