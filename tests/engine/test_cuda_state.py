"""The particles' arrays that a step on the GPU makes there (colsim.engine.cuda_state, issue 46):
the program's masses and free forces, the increments, the next state and its predicted motion are
the host's, bit for bit (their arithmetic is sums, divisions and products rounded once each, and
the kernels keep every product that a sum reads apart from it), so they serve as the host arrays'
device copies; and a step made from them copies none of them from the host. The kernels run on
numba's CUDA simulator here (conftest sets NUMBA_ENABLE_CUDASIM=1 unless told otherwise)."""
import numpy as np
import pytest

from colsim.engine.contacts import detect, swept_midpoints
from colsim.engine.program import assemble
from colsim.engine.state import ContactLaw, StepSettings, Walls
from colsim.engine.backend import advance, predicted_displacement
from colsim.stages.pack import starting_cloud

cuda_state = pytest.importorskip("colsim.engine.cuda_state", reason="numba.cuda is not importable")

from colsim.engine.backend import HOST  # noqa: E402
from colsim.engine.backends import make_backend  # noqa: E402

#: the GPU's back-end (numba's simulator here), and both by device
CUDA = make_backend("cuda")
BACKENDS = {"cuda": CUDA, "cpu": HOST}


def _moving_cloud(seed: int):
    """The pack stage's 60-sphere cloud (diameters 0.25-0.5), settled closer, moving and spinning."""
    state = starting_cloud(60, 1.0, seed=seed)
    state.position[:, 2] *= 0.5
    rng = np.random.default_rng(seed)
    state.velocity[:] = rng.normal(scale=0.3, size=(state.n, 3))
    state.angular_velocity[:] = rng.normal(scale=2.0, size=(state.n, 3))
    return state


def _nudged_stack():
    """(state, settings): 12 spheres (diameter 0.5) stacked 2 x 2 x 3 in a cylinder of radius 0.65
    on the floor (benchmarks/device_copies.py's stack), nudged sideways; the collapse's law, dt 0.02."""
    from colsim.engine.state import ParticleState

    grid = np.array([[x, y, z] for x in (-0.26, 0.26) for y in (-0.26, 0.26) for z in (0.25, 0.76, 1.27)])
    state = ParticleState.at_rest(grid, np.full(len(grid), 0.25))
    state.velocity[:, :2] = np.random.default_rng(12).normal(scale=0.2, size=(state.n, 2))
    return state, StepSettings(dt=0.02, law=ContactLaw.uniform(0.577, 0.12),
                               walls=Walls(floor=True, cylinder_radius=0.65))


def _kept(array):
    from colsim.engine.cuda_operator import kept_device_copy

    kept = kept_device_copy(array)
    assert kept is not None
    return kept.copy_to_host()


def _copies_to_device(monkeypatch) -> list:
    """(bytes, {(file, function) of each frame on its stack}) of each array copied from the host,
    from now until monkeypatch.undo()."""
    import os
    import traceback

    from numba import cuda

    copied = []

    def record(array):
        frames = {(os.path.basename(f.filename), f.name) for f in traceback.extract_stack()}
        copied.append((np.asarray(array).nbytes, frames))

    to_device = cuda.to_device
    monkeypatch.setattr(cuda, "to_device", lambda array, *args, **kwargs: (
        record(array), to_device(array, *args, **kwargs))[1])
    device_array = type(cuda.device_array(1))
    into_device = device_array.copy_to_device
    monkeypatch.setattr(device_array, "copy_to_device", lambda self, source, *args, **kwargs: (
        record(source) if isinstance(source, np.ndarray) else None, into_device(self, source, *args, **kwargs))[1])
    return copied


def test_the_device_makes_the_host_s_arrays_bit_for_bit(monkeypatch):
    """A step's chain on a moving, spinning cloud, with a time step and a gravity whose products
    round: the program's masses and free forces (assemble), the increments from a B' lam on the
    device, the next state (advance) and its predicted motion, and the swept midpoints, each made on
    the device alone (no host array until read), and each, once read, equal to the host's to the bit,
    read-only and kept as the host array's device copy. The next step's program and motion are made
    from the first's with no copy from the host (the particles' masses were copied once, for their
    radii)."""
    from numba import cuda

    state = _moving_cloud(seed=8)
    settings = StepSettings(dt=0.0137, gravity=(0.31, -0.17, -9.81), walls=Walls(floor=True, cylinder_radius=1.0))
    predicted = CUDA.predicted(state, settings)
    assert isinstance(predicted, cuda_state.DeviceParticleArray)
    np.testing.assert_array_equal(np.asarray(predicted), state.velocity * settings.dt
                                  + np.asarray(settings.gravity) * settings.dt**2)
    np.testing.assert_array_equal(_kept(np.asarray(predicted)), np.asarray(predicted))
    contacts = detect(state, settings.walls, ContactLaw.uniform(0.5, 0.1), predicted, 0.05)
    program = CUDA.assemble(state, contacts, settings.dt, settings.gravity)
    assert isinstance(program, cuda_state.DeviceProgram) and not {"mass", "fbar"} & set(vars(program))
    on_host = assemble(state, contacts, settings.dt, settings.gravity)
    for name in ("mass", "fbar"):
        np.testing.assert_array_equal(getattr(program, name), getattr(on_host, name))
        np.testing.assert_array_equal(_kept(getattr(program, name)), getattr(program, name), err_msg=name)
        assert not getattr(program, name).flags.writeable
    hx = np.random.default_rng(9).normal(scale=50.0, size=6 * state.n)
    u = cuda_state.increments_on_device(program, cuda.to_device(hx))
    np.testing.assert_array_equal(u.copy_to_host(), (program.fbar + hx) / program.mass)
    moved = CUDA.advance(state, u, settings.dt)
    expected = advance(state, u.copy_to_host(), settings.dt)
    assert isinstance(moved, cuda_state.DeviceState) and not set(cuda_state.MOVING) & set(vars(moved))
    assert moved.time == expected.time
    for name in cuda_state.MOVING:
        np.testing.assert_array_equal(getattr(moved, name), getattr(expected, name))
        np.testing.assert_array_equal(_kept(getattr(moved, name)), getattr(moved, name), err_msg=name)
    with pytest.raises(ValueError, match="read-only"):
        moved.position[0, 0] = 0.0   # its device copy would not follow: a change fails loudly

    copied = _copies_to_device(monkeypatch)
    following = CUDA.predicted(moved, settings)
    next_program = CUDA.assemble(moved, contacts, settings.dt, settings.gravity)
    monkeypatch.undo()
    assert [size for size, _ in copied] == []
    np.testing.assert_array_equal(np.asarray(following), predicted_displacement(moved, settings))
    np.testing.assert_array_equal(next_program.fbar, assemble(moved, contacts, settings.dt, settings.gravity).fbar)
    midpoint, _ = swept_midpoints(moved, np.asarray(following), 0.05, 0.5)
    made = cuda_state.midpoints_on_device(cuda_state.state_array_on_device(moved, "position"), following.on_device)
    np.testing.assert_array_equal(made.copy_to_host(), midpoint)


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_what_a_step_reads_of_the_device_s_arrays_is_measured_there():
    """The kinetic energy, the floor's and the cylinder's largest overlaps (a DeviceState's) and the
    stopping rule's lengths (a DeviceProgram's) are summed on the device in another order than
    numpy's: equal to the host's within n units in the last place (a sum of n terms of one sign
    reordered; the largest overlaps, a subtraction and a maximum, exactly, and the cylinder's to 4
    units in the last place of the cylinder's radius: rho = sqrt(x^2 + y^2) against np.hypot, a unit
    or two, and a card fuses its multiply-add); the overlaps then need no particle's on the host. 700
    spheres, three of the simulator's blocks, some pushed into the floor and the cylinder."""
    from numba import cuda

    from colsim.engine.cones import force_floor, length_scale, mean_diameter

    state = starting_cloud(700, 3.0, seed=11)
    rng = np.random.default_rng(12)
    state.velocity[:] = rng.normal(scale=0.3, size=(state.n, 3))
    state.angular_velocity[:] = rng.normal(scale=2.0, size=(state.n, 3))
    state.position[:5, 2] = state.radius[:5] - 0.003   # 0.003 into the floor
    walls = Walls(floor=True, cylinder_radius=float((np.hypot(*state.position[:, :2].T) + state.radius).max()) - 0.004)
    settings = StepSettings(dt=0.0137, walls=walls)
    moved = CUDA.advance(state, cuda.to_device(np.zeros(6 * state.n)), settings.dt)   # on the device alone
    on_host = advance(state, np.zeros(6 * state.n), settings.dt)
    assert isinstance(moved, cuda_state.DeviceState)
    # nothing moved: the velocities are zero; the last state's energy, measured on the device
    assert moved.kinetic_energy() == (0.0, 0.0)
    device_state = cuda_state.DeviceState.made_on_device(state, {name: cuda.to_device(getattr(state, name))
                                                                 for name in cuda_state.MOVING}, state.time)
    eps = state.n * np.finfo(float).eps
    np.testing.assert_allclose(device_state.kinetic_energy(), state.kinetic_energy(), rtol=eps, atol=0)
    for tolerance in (0.01, 0.001):   # within: measured on the device; beyond: on the host, each particle's
        gpu, cpu = ((CUDA if s is moved else HOST).overlaps(s, walls, tolerance) for s in (moved, on_host))
        assert (gpu.cylinder is None) == (tolerance == 0.01)
        assert gpu.largest_floor == cpu.largest_floor == pytest.approx(0.003, rel=1e-9)
        assert cpu.largest == pytest.approx(0.004, rel=1e-9)   # the cylinder's
        assert abs(gpu.largest - cpu.largest) <= 4 * np.spacing(walls.cylinder_radius)
    assert set(cuda_state.MOVING) & set(vars(moved)) == {"position"}   # read by the check beyond the tolerance
    program = CUDA.assemble(device_state, None, settings.dt, settings.gravity)
    host_program = assemble(state, None, settings.dt, settings.gravity)
    assert length_scale(program) == pytest.approx(length_scale(host_program), rel=eps, abs=0)
    assert mean_diameter(program) == pytest.approx(mean_diameter(host_program), rel=eps, abs=0)
    assert force_floor(program, 1.0) == pytest.approx(force_floor(host_program, 1.0), rel=eps, abs=0)
    assert not {"mass", "fbar"} & set(vars(program))


def test_the_inverse_masses_are_the_host_s():
    """1 / mass on the device (APGD's set-up takes it there) is numpy's, bit for bit."""
    from numba import cuda

    mass = np.random.default_rng(10).uniform(0.01, 300.0, 1000)
    np.testing.assert_array_equal(cuda_state.inverses_on_device(cuda.to_device(mass)).copy_to_host(), 1.0 / mass)


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_a_step_on_the_gpu_copies_no_particle_array_to_the_device(monkeypatch):
    """The second step of a small collapse on the GPU (APGD's kernels and the detection there: 12
    spheres stacked 2 x 2 x 3 in a cylinder, nudged sideways): nothing goes to the device (the
    particles' positions, motion, masses and free forces are made there from the step before, and
    the floor's and the cylinder's contacts there too; a copy made on purpose shows the count works),
    and none of the particles' arrays, increments or forces comes back: the new state's arrays are on
    the device alone until read (the kinetic energy and the walls' overlaps are measured there); the
    end is the CPU's run of the same steps, to 1e-12 of the motion (the bound of the stepper's GPU
    test)."""
    import traceback

    from numba import cuda

    from colsim.engine.stepper import run
    from colsim.solvers.apgd import ApgdSolver

    state, settings = _nudged_stack()
    steps = run(state, settings, 2, ApgdSolver(tolerance=1e-4, backend=CUDA), backend=CUDA)
    next(steps)
    copied = _copies_to_device(monkeypatch)
    device_array = type(cuda.device_array(1))
    to_host, host_copies = device_array.copy_to_host, []

    def counted_to_host(self, *args, **kwargs):
        if any(f.name == "host_copy" for f in traceback.extract_stack()):
            host_copies.append(self.nbytes)
        return to_host(self, *args, **kwargs)

    monkeypatch.setattr(device_array, "copy_to_host", counted_to_host)
    cuda.to_device(np.zeros(3))   # the one copy the count must see
    cuda_state.host_copy(cuda.to_device(np.zeros(5)))   # and the one copy back
    later = list(steps)
    monkeypatch.undo()
    assert [size for size, _ in copied] == [24, 40], copied
    assert host_copies == [40]
    assert isinstance(later[-1].state, cuda_state.DeviceState)
    assert not set(cuda_state.MOVING) & set(vars(later[-1].state))
    cpu = list(run(state, settings, 2, ApgdSolver(tolerance=1e-4)))
    moved = np.abs(cpu[-1].state.position - state.position).max()
    assert moved > 0.01
    np.testing.assert_allclose(later[-1].state.position, cpu[-1].state.position, rtol=0, atol=1e-12 * moved)


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_a_gpu_run_goes_on_after_a_step_solved_on_the_cpu():
    """A step on the GPU whose APGD reaches its cap is solved again by Clarabel on the host (auto's
    fallback): its increments have no device copy, so its state has none, and the next GPU step
    copies the particles' arrays from the host again. The same steps on the CPU (the same fallbacks)
    end on the same positions, to 1e-12 of the motion."""
    from colsim.engine.stepper import run
    from colsim.solvers.registry import AutoSolver

    state, settings = _nudged_stack()
    ends = {}
    for kernel, backend in (("cuda", CUDA), ("numba", HOST)):
        capped = next(run(state, settings, 1, AutoSolver(max_iter=10, apgd={"backend": backend}), backend=backend))
        after = next(run(capped.state, settings, 1, AutoSolver(apgd={"backend": backend}), first_step=1,
                         carry=capped.carry, backend=backend))
        backends = [result.diagnostics.solver_backend for result in (capped, after)]
        assert backends == ["clarabel-fallback", "apgd"], backends
        ends[kernel] = after.state.position
    moved = np.abs(ends["numba"] - state.position).max()
    np.testing.assert_allclose(ends["cuda"], ends["numba"], rtol=0, atol=1e-12 * moved)
