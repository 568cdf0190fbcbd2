"""The packing stage (colsim.stages.pack): free fall into the cylinder, in one cloud or in layers."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from colsim.engine.contacts import overlaps, touching_pairs
from colsim.engine.state import ParticleState, Walls
from colsim.io.checkpoint import CheckpointError
from colsim.solvers import AutoSolver
from colsim.stages.pack import pack
from colsim.stages.pour_geometry import column_height, solid_fraction
from colsim.stages.settings import PackSettings

from helpers import PACKING_R0 as R0


def test_packing_is_settled_tall_enough_and_dense(packing):
    state = packing.state
    assert column_height(state) >= 3.0
    # Random loose packings of frictionless polydisperse spheres: the paper reports 0.58 with
    # mu = 0 filling; allow 0.52-0.66 for a column only 6 grains across (wall effects).
    assert 0.52 < packing.solid_fraction < 0.66
    radial = np.hypot(state.position[:, 0], state.position[:, 1]) + state.radius
    assert radial.max() <= R0 * (1 + 1e-3)            # inside the cylinder, up to 0.1 % of r0
    assert (state.position[:, 2] - state.radius).min() > -0.01 * 0.25
    assert np.all(state.velocity == 0)


def test_friction_while_filling_packs_looser():
    """pack(mu = 0.5) against the paper's mu = 0, same cloud (r0 = 1, 200 spheres, auto: APGD):
    measured 0.576 and 0.534 (0.566 and 0.529 with the 180 spheres of clouds sized at 0.58).
    Friction holds grains where they first touch, so the solid fraction must drop; by at least
    0.02 (seeds 1-4 gave 0.566-0.571 without friction, 0.521-0.533 with)."""
    fractions = [pack(PackSettings(r0=1.0, height=2.0, mu=mu), np.random.default_rng([1, 0]),
                        AutoSolver(apgd={"tolerance": 1e-3}))
                 .solid_fraction for mu in (0.0, 0.5)]
    assert fractions[1] < fractions[0] - 0.02


def test_filling_in_layers_fixes_the_buried_spheres_and_overlaps_nothing():
    """pack with clouds of 0.8 settled thickness, fixing spheres at rest 0.5 below the surface
    (r0 = 1.5, height 3.5, about 520 spheres, auto: APGD): several clouds, spheres fixed while
    filling, and the finished packing, measured afresh with nothing fixed, overlaps by at most the
    stepper's tolerance (1 % of the smallest diameter): no sphere sank into a fixed one. Its forces
    hold every touching pair (gap below 1e-3 of the smallest diameter), those between fixed
    spheres from when they last moved: the collapse's first step starts warm from them. The solid fraction lies in the range of the single pour's
    test above (0.52-0.66)."""
    solver = AutoSolver(apgd={"tolerance": 1e-3})
    settings = PackSettings(r0=R0, height=3.5, layer_height=0.8, freeze_depth=0.5)
    result = pack(settings, np.random.default_rng([3, 0]), solver)
    state = result.state
    assert result.clouds >= 4 and result.most_fixed > 100
    assert column_height(state) >= 3.5
    smallest = 2.0 * state.radius.min()
    assert overlaps(state, Walls(floor=True, cylinder_radius=R0)).largest <= 0.01 * smallest
    assert 0.52 < result.solid_fraction < 0.66
    touching = {(int(i), int(j)) for i, j in zip(*touching_pairs(state, 1e-3 * smallest))}
    forces = result.contact_forces
    assert np.all(forces.j >= -1)      # numbered as the packing: no fixed-sphere code survives
    stored = {(min(i, j), max(i, j)) for i, j in zip(forces.i.tolist(), forces.j.tolist()) if j >= 0}
    assert touching <= stored


def test_solid_fraction_of_a_known_arrangement():
    # one sphere of radius 0.5 centred at z = 0.5 in a cylinder of radius 1, height 1:
    # (4/3 pi 0.125) / (pi 1) = 1/6
    state = ParticleState.at_rest([[0, 0, 0.5]], [0.5])
    assert solid_fraction(state, 1.0, 1.0) == pytest.approx(1 / 6, rel=1e-12)
    # cut at mid-height: half the sphere in half the volume
    assert solid_fraction(state, 1.0, 0.5) == pytest.approx(1 / 6, rel=1e-12)


class _Killed(Exception):
    pass


def _killed_after(steps: int):
    """A progress callback that stops the packing, as a kill would, at its `steps`-th step."""
    seen = [0]

    def progress(diagnostics, state):
        seen[0] += 1
        if seen[0] == steps:
            raise _Killed
    return progress


@pytest.mark.parametrize("layers", [None, 0.6], ids=["one-cloud", "layers"])
def test_a_killed_packing_resumes_from_its_checkpoint_to_the_same_packing(tmp_path, layers):
    """Killed after 23 steps with a checkpoint every 10, then run again: the same spheres, forces
    and step count as a packing never stopped, to the last bit (the checkpoint holds the state, the
    forces by pair, the margin and the generator's state), also when run again with another
    checkpoint interval and a larger max_steps (issue 45.4: neither changes a step); a checkpoint of
    other settings is refused, not used nor replaced."""
    settings = PackSettings(r0=1.0, height=1.2, layer_height=layers, freeze_depth=0.3, dt=0.04, rest_energy=0.05)
    whole = pack(settings, np.random.default_rng(11), AutoSolver())
    checkpoint = tmp_path / "pack.checkpoint"
    with pytest.raises(_Killed):
        pack(replace(settings, checkpoint_every=10), np.random.default_rng(11), AutoSolver(),
             checkpoint=checkpoint, progress=_killed_after(23))
    assert checkpoint.is_file()
    with np.load(checkpoint) as saved:
        first_wall, first_cpu = float(saved["elapsed"]), float(saved["cpu"])
    resumed = pack(replace(settings, checkpoint_every=7, max_steps=9000), np.random.default_rng(11), AutoSolver(),
                   checkpoint=checkpoint)
    assert resumed.steps == whole.steps and resumed.clouds == whole.clouds
    # the times cover both segments: at least what the first had spent when it saved
    assert 0 < first_cpu <= resumed.cpu_time and 0 < first_wall <= resumed.wall_time
    for name in ("position", "velocity", "angular_velocity", "radius"):
        np.testing.assert_array_equal(getattr(resumed.state, name), getattr(whole.state, name))
    for name in ("i", "j", "family", "force", "rolling"):
        np.testing.assert_array_equal(getattr(resumed.contact_forces, name), getattr(whole.contact_forces, name))
    # every step's diagnostics, over both segments, as the packing never stopped had them (wall times aside)
    assert [d.step for d in resumed.diagnostics] == list(range(1, whole.steps + 1))
    for name in ("time", "n_contacts", "kinetic_energy", "solver_iterations", "redone"):
        assert [getattr(d, name) for d in resumed.diagnostics] == [getattr(d, name) for d in whole.diagnostics]
    with pytest.raises(CheckpointError, match="another run"):
        pack(settings, np.random.default_rng(12), AutoSolver(), checkpoint=checkpoint)


def test_a_slow_packing_writes_its_checkpoint_by_the_clock_too(tmp_path, monkeypatch):
    """With checkpoint_every beyond the packing's steps, a checkpoint still comes when
    CHECKPOINT_INTERVAL_S has passed (here 0 s: at every step), and the packing killed after 23
    steps resumes from it to the same packing as one never stopped."""
    from colsim.stages import stopwatch

    settings = PackSettings(r0=1.0, height=1.2, dt=0.04, rest_energy=0.05)
    whole = pack(settings, np.random.default_rng(11), AutoSolver())
    monkeypatch.setattr(stopwatch, "CHECKPOINT_INTERVAL_S", 0.0)
    checkpoint = tmp_path / "pack.checkpoint"
    with pytest.raises(_Killed):
        pack(replace(settings, checkpoint_every=10**6), np.random.default_rng(11), AutoSolver(),
             checkpoint=checkpoint, progress=_killed_after(23))
    with np.load(checkpoint) as saved:
        assert int(saved["loop_steps"]) == 22     # the last step before the kill
    resumed = pack(replace(settings, checkpoint_every=10**6), np.random.default_rng(11), AutoSolver(),
                   checkpoint=checkpoint)
    assert resumed.steps == whole.steps
    np.testing.assert_array_equal(resumed.state.position, whole.state.position)


@pytest.mark.slow
def test_a_pour_on_the_gpu_takes_the_cpu_s_steps():
    """`colsim pack --device cuda` (issue 46.4): the pour's first 9 steps (76 spheres falling into
    r0 = 0.8; the first contact at step 7, 30 APGD iterations: the simulator takes seconds an
    iteration) with APGD's iterations on the GPU, here numba's CUDA simulator, against its compiled
    CPU kernels, with the CLI's settings (auto, the packing's tolerance). The rest of a step is the
    CPU's, so both take the same steps: the same iterations a step, and positions within 1e-9 of a
    diameter (the GPU's sums differ from the CPU's by rounding only). max_steps stops the pour there."""
    from colsim.cli.commands import _backend, _pack_solver
    from colsim.stages.settings import SolverSettings

    settings = PackSettings(r0=0.8, height=0.8, max_steps=9)
    runs = {}
    for device in ("cpu", "cuda"):
        steps = []
        solving = SolverSettings(device=device)
        backend = _backend(solving)
        with pytest.raises(RuntimeError, match="not at rest after 9 steps"):
            pack(settings, np.random.default_rng([1, 2024]), _pack_solver(solving, backend), backend=backend,
                 progress=lambda diagnostics, state: steps.append((diagnostics, state.position.copy())))
        runs[device] = steps
    cpu, gpu = runs["cpu"], runs["cuda"]
    assert len(cpu) == len(gpu) == 9
    assert sum(d.solver_iterations for d, _ in cpu) > 0 and cpu[-1][0].n_contacts > 0
    assert [d.solver_iterations for d, _ in gpu] == [d.solver_iterations for d, _ in cpu]
    diameter = 2 * 0.25
    assert np.abs(gpu[-1][1] - cpu[-1][1]).max() <= 1e-9 * diameter
