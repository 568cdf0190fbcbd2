"""APGD's iterations on the GPU (colsim.engine.cuda_apgd): the CPU's decisions
(colsim.engine.apgd_iteration.decide), made on the device between the CUDA kernels, follow the CPU's, and a
solve on the device meets Clarabel as the CPU's does. They run on numba's CUDA simulator here (conftest sets
NUMBA_ENABLE_CUDASIM=1 unless told otherwise), on a GPU where there is one.

Bounds: a kernel against its CPU twin 1e-12 relative (the same arithmetic; the sums over contacts
and bodies are added in another order, per block (of cuda_operator.THREADS) then by block, so they differ by rounding,
about 1e-16 a term); the relative residuals also 1e-12 absolute, since a force on its cone's
boundary has a violation of rounding size, which a GPU's fused multiply-adds change (on an H200 the
dual residual was 1.6e-17 against the CPU's 5.5e-17); 30 iterations 1e-10 of the largest force
(rounding carried through as many steps, with the same restarts and backtracks); a whole solve: the
bounds of test_apgd's test_agrees_with_clarabel (1e-3)."""
import numpy as np
import pytest

from colsim.solvers import AutoSolver, ClarabelSolver, defaults
from colsim.engine.apgd_iteration import _trial_step
from colsim.solvers.apgd import ApgdSolver
from solver_cases import collapse_program, mid_collapse

apgd_cuda = pytest.importorskip("colsim.engine.cuda_apgd", reason="numba.cuda is not importable")
cuda = pytest.importorskip("numba").cuda
from colsim.engine.backends import make_backend  # noqa: E402 (after the skip)

#: the GPU's back-end (numba's simulator here)
CUDA = make_backend("cuda")

#: spheres of the program: the simulator runs every thread of a block (128) as a Python thread, about
#: 1 s an iteration at this size, 3.4 s at the whole pile's 90 spheres
SPHERES = 16


@pytest.fixture(scope="module")
def program(solver_pile):
    """One collapse step of the pile's lowest spheres, mid-collapse: contacts between spheres, with
    the floor and with the cylinder, some sliding."""
    state = mid_collapse(solver_pile)
    lowest = np.zeros(state.n, dtype=bool)
    lowest[np.argsort(state.position[:, 2])[:SPHERES]] = True
    program = collapse_program(state.subset(lowest))[0]
    assert program.m > SPHERES and np.all(program.mu > 0) and np.any(program.mu_r > 0)
    return program


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
@pytest.mark.parametrize("start", ["warm", "cold"])
def test_the_start_made_on_the_device_equals_the_cpu_s(program, start):
    """Everything ApgdSolver.prepare makes, made on the device: the row scales, the scaled
    coefficients, c, the first iterate (a warm start's forces projected onto the scaled cones, or
    zero), T x and the Lipschitz estimate (12 power iterations on the kernels): the CPU's to 1e-12
    (sums in another order); the forces S z to 1e-12 too. (The gradient at y is taken by each trial
    step on the device: the next test's x_new shows it.)"""
    warm = ApgdSolver().solve(program).forces if start == "warm" else None
    cpu = ApgdSolver().prepare(program, warm)
    gpu = ApgdSolver(backend=CUDA).prepare(program, warm)
    assert gpu.is_warm() == cpu.is_warm() == (start == "warm")
    assert gpu.lip == pytest.approx(cpu.lip, rel=1e-12) and (gpu.theta, gpu.beta) == (cpu.theta, cpu.beta)
    for device, host in ((gpu.geometry.s, cpu.scaling.ravel()), (gpu.mu_s, cpu.mu_s), (gpu.mu_r_s, cpu.mu_r_s),
                         (gpu.c, cpu.c), (gpu.x, cpu.x), (gpu.x_prev, cpu.x_prev), (gpu.hx, cpu.hx)):
        np.testing.assert_allclose(device.copy_to_host(), host, rtol=0, atol=1e-12 * max(np.abs(host).max(), 1e-300))
    np.testing.assert_allclose(gpu.forces(), cpu.forces(), rtol=0, atol=1e-12 * np.abs(cpu.forces()).max() + 1e-300)


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_a_trial_step_and_the_residuals_equal_the_cpu_kernels(program):
    cpu = ApgdSolver().prepare(program)
    gpu = ApgdSolver(backend=CUDA).prepare(program)
    x_new, h_new = np.empty_like(cpu.x), np.empty_like(cpu.hx)
    apgd_cuda.trial_step(gpu.x_slots, gpu.h_slots, gpu.control, gpu.c, gpu.geometry, gpu.mu_s, gpu.mu_r_s,
                         gpu.inv_mass, gpu.parts)   # its gradient at y = x taken on the device
    ours = gpu.parts.copy_to_host().sum(axis=1)   # the blocks' sums (the step 1/lip and beta from the device)
    theirs = _trial_step(cpu.x, cpu.x_prev, 0.0, cpu.g, x_new, 1.0 / cpu.lip, h_new, cpu.hy, cpu.geometry, cpu.mu_s,
                         cpu.mu_r_s, cpu.inv_mass, 1)
    np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-300)
    for device, host in ((gpu.x_new, x_new), (gpu.h_new, h_new)):
        np.testing.assert_allclose(device.copy_to_host(), host, rtol=1e-12, atol=1e-12 * np.abs(host).max())
    for run in (cpu, gpu):
        run.iterate(10)
    for scale, floor in ((1.0, 1e-6), (1e-3, 1e-2)):
        expected = cpu.residuals(program.mu, program.mu_r, scale, floor)
        found = gpu.residuals(program.mu, program.mu_r, scale, floor)
        assert found == pytest.approx(expected, rel=1e-12, abs=1e-12)   # see the module's docstring


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_thirty_iterations_follow_the_cpu_s(program):
    """The same control flow on both kernel sets: the same restarts and backtracks, the same
    Lipschitz estimate and momentum, and the iterate to rounding."""
    cpu = ApgdSolver().prepare(program)
    gpu = ApgdSolver(backend=CUDA).prepare(program)
    for run in (cpu, gpu):
        run.iterate(10)
        run.iterate(20)   # the momentum carried from one call to the next
    assert (gpu.backtracks, gpu.restarts) == (cpu.backtracks, cpu.restarts)
    assert gpu.lip == pytest.approx(cpu.lip, rel=1e-12) and gpu.theta == pytest.approx(cpu.theta, rel=1e-12)
    x = cpu.host_x()
    np.testing.assert_allclose(gpu.host_x(), x, rtol=0, atol=1e-10 * np.abs(x).max())


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
@pytest.mark.parametrize("row", [1, 32])
def test_the_small_decision_block_gives_the_large_one_s_bits(row):
    """A row of at most FEW_DECIDE_THREADS block sums: the 32-thread block adds them by the same tree
    as the 1,024-thread one without its levels that add zeros, so the two decide alike to the bit
    (lip, theta, beta, the slot and the counts), on accepted and rejected trial steps, with and
    without a restart."""
    rng = np.random.default_rng(row)
    lip, outcomes = 0.5, set()
    for descent, uphill in ((4.0, -1.0), (0.25, -1.0), (0.25, 1.0)):   # rejected; accepted; restarted
        moved = np.abs(rng.normal(size=row))   # ||x_new - y||^2 by block
        parts = np.stack([moved, uphill * np.abs(rng.normal(size=row)), descent * lip * moved])
        start = np.zeros(apgd_cuda.CONTROL_SIZE)
        start[[apgd_cuda.LIP, apgd_cuda.THETA, apgd_cuda.BETA, apgd_cuda.LIP_DECAY]] = lip, 0.7, 0.3, 0.9
        after = []
        for kernel, threads in ((apgd_cuda._decide_kernel, apgd_cuda.DECIDE_THREADS),
                                (apgd_cuda._decide_kernel_few, apgd_cuda.FEW_DECIDE_THREADS)):
            control = cuda.to_device(start)
            kernel[1, threads](cuda.to_device(parts), control)
            after.append(control.copy_to_host())
        np.testing.assert_array_equal(after[1], after[0])
        outcomes.add((after[0][apgd_cuda.ACCEPTED], after[0][apgd_cuda.RESTARTS]))
    assert outcomes == {(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)}, outcomes   # every branch of the decision


def test_a_solve_on_the_device_agrees_with_clarabel(program):
    """The device's solve, its stopping check included, warm-started from the CPU's answer (a cold
    solve takes hundreds of iterations, minutes on the simulator): it stops at its first check, and
    meets Clarabel (at 1e-10) within test_apgd's bounds, 1e-3 on the velocities and the net forces."""
    warm = ApgdSolver().solve(program).forces
    sol = ApgdSolver(backend=CUDA).solve(program, warm_start=warm)
    assert sol.info["kernel"] == "cuda" and sol.info["start"] == "warm" and sol.iterations == 10
    # the forces stay on the device until read: the step's warm start takes them there
    assert "forces" not in vars(sol) and sol.resident_forces() is sol.on_device
    from colsim.engine.cuda_operator import kept_device_copy

    assert kept_device_copy(sol.forces) is sol.on_device
    assert sol.info["primal"] <= 1e-5 and sol.info["complementarity"] <= 1e-5
    expected = program.increments(sol.forces)   # the device's hx, B' lam, is the host's product
    np.testing.assert_allclose(sol.increments, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    ref = ClarabelSolver(tolerance=1e-10).solve(program)
    du = np.linalg.norm(sol.increments - ref.increments) / np.linalg.norm(ref.increments)
    net, net_ref = (program.jacobian.T @ forces.ravel() for forces in (sol.forces, ref.forces))
    assert du <= 1e-3 and np.linalg.norm(net - net_ref) <= 1e-3 * np.linalg.norm(net_ref), du


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_float32_storage_holds_the_nearest_float32_and_checks_in_float64(program):
    """storage='float32': the trial steps' slots and contact arrays (NARROW_GEOMETRY, the wrenches)
    hold the float64 ones' nearest float32, the check's stay float64. After ten iterations the iterate
    it gives (x, widened) is the stored one exactly, hx its T x and the residuals the CPU's at it, to
    the bounds above (1e-12: sums in another order): the check is float64's, only the iterate rounds."""
    cpu = ApgdSolver().prepare(program, ApgdSolver().solve(program).forces)
    gpu = ApgdSolver(backend=CUDA, storage="float32").prepare(program, cpu.forces())
    for name in (*apgd_cuda.NARROW_GEOMETRY, "work"):
        stored, wide = getattr(gpu.trial_geometry, name), getattr(gpu.geometry, name)
        assert (stored.dtype, wide.dtype) == (np.float32, np.float64), name
        if name != "work":   # room for the wrenches, written before read
            assert np.array_equal(stored.copy_to_host(), wide.copy_to_host().astype(np.float32)), name
    start = gpu.x_slots[0].copy_to_host()
    assert start.dtype == np.float32 and np.array_equal(start, gpu.host_x().astype(np.float32))
    gpu.iterate(10)
    stored = gpu._role(gpu.x_slots, apgd_cuda.X).copy_to_host()
    assert stored.dtype == np.float32 and np.array_equal(gpu.host_x(), stored.astype(np.float64))
    cpu.x = stored.astype(np.float64)
    cpu.hx = cpu.apply_T(cpu.x)
    np.testing.assert_allclose(gpu.hx.copy_to_host(), cpu.hx, rtol=0, atol=1e-12 * np.abs(cpu.hx).max())
    for scale, floor in ((1.0, 1e-6), (1e-3, 1e-2)):
        expected = cpu.residuals(program.mu, program.mu_r, scale, floor)
        assert gpu.residuals(program.mu, program.mu_r, scale, floor) == pytest.approx(expected, rel=1e-12, abs=1e-12)


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_a_solve_stored_in_float32_agrees_with_clarabel(program):
    """The float32-stored solve, warm-started as the float64 one above: it stops on its float64 check
    within the same bounds of Clarabel (1e-3), its increments B' lam of its own forces to 1e-12."""
    warm = ApgdSolver().solve(program).forces
    sol = ApgdSolver(backend=CUDA, storage="float32").solve(program, warm_start=warm)
    assert sol.info["storage"] == "float32" and sol.info["primal"] <= 1e-5 and sol.info["complementarity"] <= 1e-5
    expected = program.increments(sol.forces)
    np.testing.assert_allclose(sol.increments, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    ref = ClarabelSolver(tolerance=1e-10).solve(program)
    du = np.linalg.norm(sol.increments - ref.increments) / np.linalg.norm(ref.increments)
    net, net_ref = (program.jacobian.T @ forces.ravel() for forces in (sol.forces, ref.forces))
    assert du <= 1e-3 and np.linalg.norm(net - net_ref) <= 1e-3 * np.linalg.norm(net_ref), du


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_a_float32_solve_that_reaches_its_cap_is_made_again_in_float64(program, monkeypatch):
    """A float32-stored solve that fails (made to, here, before it iterates) is solved again from the
    same start with float64 storage, which the solution's info names; float64's own failure is the
    solver's (SolverError, for auto's Clarabel)."""
    from colsim.engine.solver_contract import SolverError

    warm = ApgdSolver().solve(program).forces
    solve, storages = ApgdSolver._solve, []

    def failing_in_float32(self, program, warm_start, step, max_iter, storage):
        storages.append(storage)
        if storage == "float32":
            raise SolverError("APGD did not converge (made to fail)", status="MaxIterations")
        return solve(self, program, warm_start, step, max_iter, storage)

    monkeypatch.setattr(ApgdSolver, "_solve", failing_in_float32)
    sol = ApgdSolver(backend=CUDA, storage="float32").solve(program, warm_start=warm)
    assert storages == ["float32", "float64"] and sol.info["storage"] == "float64" and sol.info["primal"] <= 1e-5
    assert sol.backend == defaults.FLOAT64_FALLBACK   # the step's record names the retry, under auto too
    auto = AutoSolver(apgd={"backend": CUDA, "storage": "float32"}).solve(program, warm_start=warm)
    assert auto.backend == defaults.FLOAT64_FALLBACK and auto.info["storage"] == "float64"
    with pytest.raises(SolverError, match="did not converge"):
        ApgdSolver(backend=CUDA, storage="float32", max_iter=1).solve(program)


def test_float32_storage_is_the_gpu_s_and_recorded_only_when_chosen():
    with pytest.raises(ValueError, match="float32 storage is the GPU's"):
        ApgdSolver(storage="float32")
    with pytest.raises(ValueError, match="float64, float32"):
        ApgdSolver(backend=CUDA, storage="float16")
    assert "storage" not in ApgdSolver(backend=CUDA).describe()
    assert ApgdSolver(backend=CUDA, storage="float32").describe()["storage"] == "float32"


@pytest.mark.parametrize("largest", [1.0, -1.0], ids=["pushing", "none-pushing"])
def test_the_active_contacts_counted_on_the_device_are_the_host_s(largest):
    """A solution's active contacts (normal force above 1e-8 of the largest, none when no force is
    positive) counted on the device: the host's count of the same forces, exactly (the same comparisons).
    3 THREADS + 5 contacts, so the largest is found across blocks; normal forces on either side of
    the threshold, zeros and negatives."""
    from colsim.engine.cuda_operator import THREADS
    from colsim.engine.solver_contract import ConeSolution

    rng = np.random.default_rng(4)
    forces = rng.normal(size=(3 * THREADS + 5, 5))
    forces[:, 0] = rng.choice([0.0, 5e-9, 1e-8, 2e-8, 0.3, -0.2], size=len(forces))
    if largest < 0:
        forces[:, 0] = -np.abs(forces[:, 0])
    forces[2 * THREADS + 1, 0] = largest   # the largest in size, in the third block
    solution = apgd_cuda.DeviceSolution(np.zeros(6), cuda.to_device(forces), "Solved", 0, 0.0, 0.0)
    expected = ConeSolution(np.zeros(6), forces, "Solved", 0, 0.0, 0.0).active_contacts()
    assert solution.active_contacts() == expected
    assert expected == (np.count_nonzero(forces[:, 0] > 1e-8) if largest > 0 else 0) and "forces" not in vars(solution)


def test_cuda_without_a_gpu_or_the_simulator_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(cuda, "is_available", lambda: False)
    with pytest.raises(ValueError, match="needs a CUDA GPU"):
        make_backend("cuda")


def test_the_power_iteration_starts_from_the_cpu_s_numbers_at_any_size():
    """The device's start vector is power_start's, copied on the device from its longest draw: the same
    numbers whether the sizes grow or shrink."""
    from colsim.engine.apgd_iteration import power_start

    for size in (10, 700, 50, 5000, 700):
        out = cuda.device_array(size)
        apgd_cuda._power_start_into(out)
        assert np.array_equal(out.copy_to_host(), power_start(size))
