"""The swept pairs found on the GPU (colsim.engine.cuda_contacts, issue 46.3) are the CPU's
(colsim.engine.contacts.swept_pairs), pair for pair and in the same (i, j) order. The kernels run on
numba's CUDA simulator here (conftest sets NUMBA_ENABLE_CUDASIM=1 unless told otherwise).

Exact equality: both keep a pair by the same two tests (midpoints within the reach, then the same
swept arithmetic); only a pair within a rounding of either bound could differ, and the clouds below
have none."""
import numpy as np
import pytest

from colsim.engine.contacts import swept_pairs
from colsim.engine.state import ParticleState
from colsim.stages.pack import starting_cloud

cuda_contacts = pytest.importorskip("colsim.engine.cuda_contacts", reason="numba.cuda is not importable")

from colsim.engine.backend import HOST  # noqa: E402
from colsim.engine.backends import make_backend  # noqa: E402

#: the GPU's back-end (numba's simulator here), and both by device
CUDA = make_backend("cuda")
BACKENDS = {"cuda": CUDA, "cpu": HOST}


def _moving(state: ParticleState, scale: float, seed: int) -> np.ndarray:
    """(n, 3) predicted displacements up to `scale` (length) in random directions."""
    return np.random.default_rng(seed).uniform(-scale, scale, (state.n, 3))


@pytest.mark.parametrize("scale", [0.0, 0.02, 0.2], ids=["at-rest", "a-step", "an-impact"])
def test_the_gpu_finds_the_cpu_s_swept_pairs(scale):
    """A 60-sphere cloud (the pack stage's lattice, diameters 0.25-0.5, cylinder radius 1), settled
    closer by halving its heights, its spheres at rest, moving a step's worth or an impact's."""
    state = starting_cloud(60, 1.0, seed=3)
    state.position[:, 2] *= 0.5
    predicted = _moving(state, scale, seed=4)
    i, j = cuda_contacts.swept_pairs_on_device(state, predicted, 0.05, 0.5)
    cpu_i, cpu_j = swept_pairs(state, predicted, 0.05, 0.5)
    assert len(cpu_i) >= 50   # the at-rest cloud has 60; the moving ones more
    np.testing.assert_array_equal(i, cpu_i)
    np.testing.assert_array_equal(j, cpu_j)


def test_a_sparse_cloud_gets_wider_cells_and_the_same_pairs():
    """Two tight clusters far apart (a grid of reach-wide cells would hold millions): the cells widen
    to CELLS_PER_PARTICLE a particle, and the pairs are still the CPU's."""
    cluster = starting_cloud(20, 0.8, seed=5)
    cluster.position[:, 2] *= 0.5
    position = np.vstack([cluster.position, cluster.position + [0.0, 0.0, 500.0]])
    state = ParticleState.at_rest(position, np.concatenate([cluster.radius, cluster.radius]))
    predicted = _moving(state, 0.05, seed=6)
    midpoint = state.position + 0.5 * predicted
    _, dims, _ = cuda_contacts._grid(midpoint.min(axis=0), midpoint.max(axis=0), 1.0, state.n)
    assert np.prod(dims) <= cuda_contacts.CELLS_PER_PARTICLE * state.n
    i, j = cuda_contacts.swept_pairs_on_device(state, predicted, 0.02, 0.5)
    cpu_i, cpu_j = swept_pairs(state, predicted, 0.02, 0.5)
    assert len(cpu_i) > 20 and np.all(j[i < 20] < 20)
    np.testing.assert_array_equal(i, cpu_i)
    np.testing.assert_array_equal(j, cpu_j)


def test_the_grid_s_bounds_measured_on_the_device_are_the_host_s():
    """The midpoints' box, measured on the device, is the host's to the bit (smallest and largest
    coordinates); the reach is 2 max(R_i + (1 + slack) |u_i| / 2) + margin of
    colsim.engine.contacts.swept_midpoints to 8 units in the last place (a GPU fuses up to three
    multiply-adds in R_i + (1 + slack) |u_i| / 2, each a rounding fewer, about 3 units at most; the
    simulator fuses none). 700 spheres: three blocks of the simulator's 256 threads."""
    from numba import cuda

    from colsim.engine.contacts import swept_midpoints

    state = starting_cloud(700, 3.0, seed=7)
    predicted = _moving(state, 0.1, seed=8)
    midpoint, reach = swept_midpoints(state, predicted, 0.05, 0.5)
    d_midpoint, d_predicted, d_radius = (cuda.to_device(a) for a in (midpoint, predicted, state.radius))
    lower, upper, measured = cuda_contacts._bounds(d_midpoint, d_predicted, d_radius, 0.05, 0.5)
    np.testing.assert_array_equal(lower, midpoint.min(axis=0))
    np.testing.assert_array_equal(upper, midpoint.max(axis=0))
    assert abs(measured - reach) <= 8 * np.spacing(reach)


def test_one_sphere_has_no_pairs():
    state = ParticleState.at_rest([[0.0, 0.0, 0.5]], [0.25])
    i, j = cuda_contacts.swept_pairs_on_device(state, np.zeros((1, 3)), 0.05, 0.5)
    assert i.size == j.size == 0


@pytest.mark.parametrize("redo", [False, True], ids=["first-attempt", "a-redo"])
def test_detect_on_the_gpu_gives_the_cpu_s_contacts(redo):
    """detect(device='cuda') (what the stepper asks for when APGD runs on the GPU) lists the same
    contacts, pairs, walls and all, in the same order; the pairs' and the walls' normals, tangents and
    gaps are made on the device, in the CPU's arithmetic: equal to 1e-14 (a GPU fuses multiply-adds,
    rounding once where the CPU rounds twice: a few units in the last place of numbers of order 1; its
    hypot is its own). Some pairs
    overlap by more than the step's recovery (most_recovered = 0.002), so the relaxation counts, and so
    does the outermost sphere the cylinder; two fixed spheres touch the lowest particles. A redo passes five pairs with given normals (the
    stepper's missed pairs): three among those found, whose rows they replace, and two not; the given
    pairs go after the found ones, and on the GPU they join there: nothing of the found contacts comes
    back to the host but the grid's bounds (7 numbers a block), the counts and the largest overlaps
    (8 B each, one a block)."""
    from colsim.engine.contacts import detect, overlaps
    from colsim.engine.state import CYLINDER, FLOOR, ContactLaw, FixedSpheres, Walls

    state = starting_cloud(60, 1.0, seed=3)
    state.position[:, 2] *= 0.45
    state.position[:, 2] -= (state.position[:, 2] - state.radius).min() - 0.01   # the bottom layer on the floor
    predicted = _moving(state, 0.02, seed=8)
    lowest = np.argsort(state.position[:, 2])[:2]   # two fixed spheres just under the two lowest
    below = state.position[lowest] - [[0.0, 0.0, 1e-3]] - 2.0 * state.radius[lowest, None] * [[0.0, 0.0, 1.0]]
    # the cylinder 0.004 inside the outermost sphere: it overlaps by more than the step's recovery
    cylinder = float((np.hypot(state.position[:, 0], state.position[:, 1]) + state.radius).max()) - 0.004
    walls = Walls(floor=True, cylinder_radius=cylinder, fixed=FixedSpheres(below, state.radius[lowest]))
    law = ContactLaw.uniform(0.5, 0.1)
    renormal = None
    if redo:
        i, j = swept_pairs(state, predicted, 0.05, 0.5)
        missed = [(a, b) for a, b in ((0, state.n - 1), (1, state.n - 2)) if not np.any((i == a) & (j == b))]
        assert len(missed) == 2
        i, j = np.concatenate([i[[4, 0, 7]], [a for a, _ in missed]]), np.concatenate([j[[4, 0, 7]], [b for _, b in missed]])
        tilted = state.position[j] - state.position[i] + [0.01, -0.02, 0.03]
        renormal = (i, j, tilted / np.linalg.norm(tilted, axis=1)[:, None])
    from colsim.engine.contacts import DEVICE_ARRAYS
    from colsim.engine.cuda_contacts import DeviceContacts
    from colsim.engine.cuda_operator import blocks_for

    gpu, read = _reading_back(lambda: CUDA.detect(state, walls, law, predicted, 0.05, renormal=renormal,
                                                  most_recovered=0.002))
    cpu = detect(state, walls, law, predicted, 0.05, renormal=renormal, most_recovered=0.002)
    # the contacts stay on the device, with no host array until one is read
    assert isinstance(gpu, DeviceContacts) and not set(DEVICE_ARRAYS) & set(vars(gpu))
    # the grid's bounds, the pairs' and the walls' counts and each block's largest overlap
    assert read == [56 * blocks_for(state.n), 8, 8, 8 * blocks_for(state.n)] + [8] * redo
    assert np.count_nonzero(cpu.j == -1) >= 3 and np.count_nonzero(cpu.j >= 0) >= 50   # walls and pairs
    assert np.count_nonzero(cpu.family == FLOOR) and np.count_nonzero(cpu.family == CYLINDER)   # both walls
    assert np.count_nonzero(cpu.j <= -2) == 2                                           # the fixed spheres
    pairs = cpu.j >= 0
    overlap = -(np.linalg.norm(state.position[cpu.j[pairs]] - state.position[cpu.i[pairs]], axis=1)
                - cpu.radius_i[pairs] - cpu.radius_j[pairs])
    assert overlap.max() > 0.002   # the relaxation is on for some pairs
    for name in ("i", "j", "family", "radius_i", "radius_j", "lever", "mu", "mu_r"):
        np.testing.assert_array_equal(getattr(gpu, name), getattr(cpu, name))
    for name in ("normal", "tangent1", "tangent2", "gap"):
        np.testing.assert_allclose(getattr(gpu, name), getattr(cpu, name), rtol=0, atol=1e-14)
    # a first attempt's largest pair overlap, measured on the device for the stepper's check: the
    # host's measure of the same pairs (overlaps()), to 1e-14 as the gaps; a redo's is not measured
    assert cpu.largest_pair_overlap is None
    # the arrays on the device, for the warm start and the solver: every contact's (pairs', walls',
    # fixed spheres'), the host arrays read above (the CPU's: the lever and the keys in the CPU's
    # arithmetic, which has no multiply-add to fuse), bit for bit, kept as their copies
    from colsim.engine.cuda_operator import kept_device_copy

    for name in DEVICE_ARRAYS:
        kept = kept_device_copy(getattr(gpu, name))
        np.testing.assert_array_equal(kept.copy_to_host(), getattr(gpu, name), err_msg=name)
        assert kept is gpu.device[name]
    np.testing.assert_array_equal(gpu.keys, cpu.keys)
    if redo:
        assert gpu.largest_pair_overlap is None
    else:
        np.testing.assert_allclose(gpu.largest_pair_overlap, overlap.max(), rtol=0, atol=1e-14)
        checked = overlaps(state, walls, overlap.max() + 1e-9, detected=gpu)   # within the tolerance: not measured
        assert checked.largest_pair == gpu.largest_pair_overlap and len(checked.pairs[0]) == 0
        # beyond it, the overlapping pairs are listed on the device: the CPU's search's (sorted), with
        # the normals made on the host by the same arithmetic; back come their count and bodies only
        tolerance = 0.5 * overlap.max()
        listed, read = _reading_back(lambda: overlaps(state, walls, tolerance, detected=gpu))
        searched = overlaps(state, walls, tolerance)
        order = np.lexsort((searched.pairs[1], searched.pairs[0]))
        assert len(order) >= 2 and read == [8, 16 * len(order)]
        for ours, theirs in zip(listed.pairs, searched.pairs):
            np.testing.assert_array_equal(ours, theirs[order])
        assert listed.largest_pair == gpu.largest_pair_overlap
    if redo:
        np.testing.assert_array_equal(gpu.normal[pairs][-5:], renormal[2])
        assert gpu.pair_count == np.count_nonzero(pairs)


def _reading_back(action):
    """(action(), the bytes of each copy from the device that it made)."""
    from numba import cuda

    device_array = type(cuda.device_array(1))
    to_host, read = device_array.copy_to_host, []
    device_array.copy_to_host = lambda self, *args, **kwargs: (read.append(self.nbytes),
                                                               to_host(self, *args, **kwargs))[1]
    try:
        return action(), read
    finally:
        device_array.copy_to_host = to_host


def test_the_gpu_measures_the_cpu_s_overlaps():
    """overlaps(device='cuda') (the stepper's check after a step on the GPU): the same overlapping
    pairs (the CPU's, which come in the k-d tree's order, sorted here), the same normals and largest
    overlaps, on the cloud pressed together so that about half its neighbours overlap."""
    from colsim.engine.contacts import overlaps
    from colsim.engine.state import Walls

    state = starting_cloud(60, 1.0, seed=3)
    state.position[:, 2] *= 0.45
    walls = Walls(floor=True, cylinder_radius=1.0)
    gpu, cpu = CUDA.overlaps(state, walls, 1e-3), overlaps(state, walls, 1e-3)
    order = np.lexsort((cpu.pairs[1], cpu.pairs[0]))
    assert len(order) >= 20
    for ours, theirs in zip(gpu.pairs, cpu.pairs):
        np.testing.assert_array_equal(ours, theirs[order])
    assert (gpu.largest_pair, gpu.largest_floor, gpu.largest_fixed) == (cpu.largest_pair, cpu.largest_floor,
                                                                        cpu.largest_fixed)
    np.testing.assert_array_equal(gpu.cylinder, cpu.cylinder)


def test_detect_on_the_gpu_without_contacts():
    """Two spheres far apart with no walls: no contacts, no frames kept on the device, and no pair
    overlap measured (-inf), which the overlap check takes as within any tolerance."""
    from colsim.engine.contacts import overlaps
    from colsim.engine.cuda_operator import kept_device_copy
    from colsim.engine.state import ContactLaw, Walls

    state = ParticleState.at_rest([[0.0, 0.0, 5.0], [3.0, 0.0, 5.0]], [0.5, 0.5])
    walls = Walls(floor=False)
    found = CUDA.detect(state, walls, ContactLaw.uniform(0.5, 0.1), np.zeros((2, 3)), 0.05)
    assert found.m == 0 and found.largest_pair_overlap == -np.inf
    assert kept_device_copy(found.normal) is None
    checked = overlaps(state, walls, 0.0, detected=found)
    assert checked.largest == 0.0 and len(checked.pairs[0]) == 0


def test_a_redo_on_the_gpu_with_no_pair_found():
    """A redo whose detection finds no particle pair, only the floor's contacts (two spheres on it, far
    apart), given one pair (the stepper's missed pair, with a normal given): on the device, as on the
    host, the given pair comes first and the floor's rows after it."""
    from colsim.engine.cuda_contacts import DeviceContacts
    from colsim.engine.state import ContactLaw, Walls

    state = ParticleState.at_rest([[0.0, 0.0, 0.5], [3.0, 0.0, 0.5]], [0.5, 0.5])
    walls = Walls(floor=True)
    renormal = (np.array([0]), np.array([1]), np.array([[0.6, 0.0, 0.8]]))
    gpu, cpu = (BACKENDS[device].detect(state, walls, ContactLaw.uniform(0.5, 0.1), np.zeros((2, 3)), 0.05,
                                        renormal=renormal) for device in ("cuda", "cpu"))
    assert isinstance(gpu, DeviceContacts) and gpu.pair_count == 1 and gpu.m == cpu.m == 3
    assert list(cpu.j) == [1, -1, -1]
    for name in ("i", "j", "family", "normal", "tangent1", "tangent2", "gap", "radius_i", "radius_j", "lever",
                 "mu", "mu_r", "keys"):
        np.testing.assert_array_equal(getattr(gpu, name), getattr(cpu, name), err_msg=name)


def test_a_channel_s_plane_walls_on_the_gpu_are_the_cpu_s():
    """A channel's walls (colsim.engine.state.channel_planes: back wall, sidewalls, gate) round a
    60-sphere cloud, each plane 0.004 inside its outermost sphere (an overlap beyond the step's
    recovery, most_recovered = 0.002, and beyond the overlap kept, 0.003, so that both parts of the
    relaxation count, and the pairs' overlaps under 0.003 are kept): the GPU's detection lists the CPU's
    contacts in the CPU's order, each plane's family PLANE + q and the wall's coefficients, the normals
    and gaps to 1e-14 as the floor's (a GPU may fuse the plane's multiply-adds); the overlap check
    finds the CPU's largest plane overlap (measured on the host: the same number)."""
    from colsim.engine.contacts import detect, overlaps
    from colsim.engine.state import PLANE, ContactLaw, Walls, channel_planes

    state = starting_cloud(60, 1.0, seed=3)
    state.position[:, 2] *= 0.45
    state.position[:, 2] -= (state.position[:, 2] - state.radius).min() - 0.01
    state.position[:, 0] -= (state.position[:, 0] - state.radius).min() + 0.004   # the back wall x = 0
    length = float((state.position[:, 0] + state.radius).max()) - 0.004
    width = 2.0 * float((np.abs(state.position[:, 1]) + state.radius).max()) - 0.008
    walls = Walls(floor=True, planes=channel_planes(length, width, gate=True))
    law = ContactLaw(mu=(0.5, 0.6, 0.3), mu_r=(0.1, 0.12, 0.05))
    predicted = _moving(state, 0.02, seed=8)
    gpu = CUDA.detect(state, walls, law, predicted, 0.05, most_recovered=0.002, kept=0.003)
    cpu = detect(state, walls, law, predicted, 0.05, most_recovered=0.002, kept=0.003)
    assert {PLANE, PLANE + 1, PLANE + 2, PLANE + 3} <= set(cpu.family.tolist())
    for name in ("i", "j", "family", "radius_i", "radius_j", "lever", "mu", "mu_r", "keys"):
        np.testing.assert_array_equal(getattr(gpu, name), getattr(cpu, name), err_msg=name)
    for name in ("normal", "tangent1", "tangent2", "gap"):
        np.testing.assert_allclose(getattr(gpu, name), getattr(cpu, name), rtol=0, atol=1e-14, err_msg=name)
    gpu_overlap, cpu_overlap = CUDA.overlaps(state, walls, 1.0, detected=gpu), overlaps(state, walls, 1.0)
    assert gpu_overlap.largest_plane == cpu_overlap.largest_plane == pytest.approx(0.004, abs=1e-12)


@pytest.mark.slow
def test_a_channel_s_steps_on_the_gpu_are_the_cpu_s():
    """Three steps of a box of 12 spheres sliding along a channel between its sidewalls (the gate
    gone, the wall friction 0.3, a channel collapse's overlap kept), APGD on the GPU's back-end
    (numba's simulator, about a minute) against the CPU's: the same iterations a step and positions
    within 1e-9 of a diameter (the GPU's sums differ from the CPU's by rounding only)."""
    from colsim.engine.state import ContactLaw, StepSettings, Walls, channel_planes
    from colsim.engine.stepper import run
    from colsim.solvers.registry import make_solver

    radius = 0.2
    grid = np.stack(np.meshgrid(np.arange(3), np.arange(2), np.arange(2), indexing="ij"), -1).reshape(-1, 3)
    # two rows, each against a sidewall, 0.08 apart: room for the associated law's dilation (a chain
    # fitting wall to wall exactly could not slide at all)
    width = 4.4 * radius
    position = (grid + 0.5) * 2 * radius - [0.0, 2 * radius, 0.0]
    position[:, 1] = np.sign(position[:, 1]) * (width / 2 - radius)
    moving = np.tile([0.5, 0.0, 0.0], (len(grid), 1))   # along the channel: sliding on its floor and sidewalls
    state = ParticleState(position, moving, np.zeros_like(position), np.full(len(grid), radius))
    walls = Walls(floor=True, planes=channel_planes(6 * radius, width, gate=False))
    settings = StepSettings(dt=0.01, walls=walls, law=ContactLaw(mu=(0.577, 0.577, 0.3), mu_r=(0.12, 0.12, 0.12)),
                            overlap_kept=0.005)
    runs = {device: list(run(state, settings, 3, make_solver("apgd", backend=backend), backend=backend))
            for device, backend in BACKENDS.items()}
    cpu, gpu = runs["cpu"], runs["cuda"]
    assert cpu[-1].diagnostics.n_contacts == gpu[-1].diagnostics.n_contacts > 12
    assert [r.diagnostics.solver_iterations for r in gpu] == [r.diagnostics.solver_iterations for r in cpu]
    assert np.abs(gpu[-1].state.position - cpu[-1].state.position).max() <= 1e-9 * 2 * radius
    assert np.abs(cpu[-1].state.position - state.position).max() > 1e-3   # it moved: real steps
