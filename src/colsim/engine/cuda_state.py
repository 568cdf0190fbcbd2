"""The particles' arrays of a step on the GPU, made there from the last step's (issue 46; item 4 of
the plan in docs/performance.md, "The third GPU sitting").

A step on the GPU needs, besides the contacts, each particle's position and predicted motion (for
detection) and the program's masses and free forces (for the solver); the host makes them too, for
the walls, the bookkeeping and a solver on the CPU. Each was copied from the host every step
(216 bytes a particle). Here the device makes its own from what it holds, in the host's arithmetic,
and keeps each as the device copy of the host's array
(:func:`colsim.engine.cuda_operator.keep_device_copy`):

- the program's masses (6n,) and free forces fbar (6n,), from the velocities' copies and the masses
  of the particles (copied once a run: they change only with the radii);
- the increments u = Mbar^-1 (fbar + B' lam) (6n,), from the solver's B' lam: these come back;
- the next state's positions, velocities and angular velocities, from the increments;
- the predicted motion v dt + g dt^2, from the velocities.

So after a run's first step no particle's array goes to the device; the increments come back (48
bytes a particle).
Each is the host's number, bit for bit: the arithmetic is additions, divisions and products, each
rounded once. A GPU fuses a product and a sum into one rounding where it can, so every product that
a sum reads is made by a kernel of its own (the weights m g, the motion v dt), or is exact (x + u/2).

A host array kept so must not change in place (its device copy would not follow): :func:`frozen`
makes each read-only, so a change fails loudly; so are the radii, whose masses are kept. Without a
GPU the kernels run on numba's simulator (NUMBA_ENABLE_CUDASIM=1), where
tests/engine/test_cuda_state.py compares each with the host's.
"""
from __future__ import annotations

import weakref

import numpy as np

from .cuda_launch import launch
from .cuda_operator import THREADS, blocks_for, cuda, device_copy_of, keep_device_copy, kept_device_copy

#: the particles' masses, inertias and weights on the device, by the identity of their radii's host
#: array (a state made from another by dataclasses.replace shares it), then by (density, gravity)
_particles: dict = {}


def frozen(array: np.ndarray, copy) -> None:
    """Keep `copy` as the device copy of the host array `array`, and make `array` read-only."""
    keep_device_copy(array, copy)
    array.flags.writeable = False


def particle_array_on_device(array: np.ndarray):
    """The device copy of a particle array (a state's, a predicted motion): the one kept, or one made
    now from the host's (a run's first step; the array is then read-only, :func:`frozen`)."""
    kept = kept_device_copy(array)
    if kept is None:
        kept = device_copy_of(array)
        array.flags.writeable = False
    return kept


def masses_on_device(state, gravity) -> tuple:
    """(mass (n,), inertia (n,), weight m g (n, 3)) of the particles of `state` on the device: copied
    (the first two) or made (the weights: products alone) once for their radii, density and gravity."""
    by_setting = _particles.get(id(state.radius))
    if by_setting is None:
        by_setting = _particles[id(state.radius)] = {}
        weakref.finalize(state.radius, _particles.pop, id(state.radius), None)
    key = (float(state.density), tuple(float(g) for g in gravity))
    if key not in by_setting:
        state.radius.flags.writeable = False   # the masses kept follow from these radii
        mass, inertia = state.mass_and_inertia()
        both = cuda.to_device(np.stack([mass, inertia]))
        weight = cuda.device_array((state.n, 3), dtype=np.float64)
        launch(_weight_kernel, blocks_for(state.n), THREADS, both[0], *key[1], weight)
        by_setting[key] = (both[0], both[1], weight)
    return by_setting[key]


def program_on_device(state, mass: np.ndarray, fbar: np.ndarray, dt: float, gravity) -> None:
    """Make :func:`colsim.engine.program.assemble`'s mass (6n,) = [m; I] / dt^2 (three times each)
    and fbar (6n,) = [m v / dt + m g; I w / dt] on the device, from the velocities' device copies,
    in its arithmetic, and keep them as the copies of the host's `mass` and `fbar`."""
    n = state.n
    if n == 0:
        return
    particle_mass, inertia, weight = masses_on_device(state, gravity)
    velocity, angular = particle_array_on_device(state.velocity), particle_array_on_device(state.angular_velocity)
    made = cuda.device_array((2, 6 * n), dtype=np.float64)
    launch(_program_kernel, blocks_for(n), THREADS, particle_mass, inertia, weight, velocity, angular, float(dt),
           float(dt) ** 2, made[0], made[1])
    frozen(mass, made[0])
    frozen(fbar, made[1])


def increments_on_device(fbar: np.ndarray, hx, mass: np.ndarray) -> np.ndarray:
    """(6n,) u = (fbar + hx) / mass, made on the device from hx = B' lam there and the program's
    fbar and mass (their device copies): the host's copy, which keeps the device's as its own."""
    u = cuda.device_array(len(mass), dtype=np.float64)
    launch(_increments_kernel, blocks_for(len(mass)), THREADS, device_copy_of(fbar), hx, device_copy_of(mass), u)
    host = u.copy_to_host()
    frozen(host, u)
    return host


def inverses_on_device(mass):
    """1 / mass on the device, from the device array `mass` (a division: the host's bits)."""
    made = cuda.device_array(mass.shape[0], dtype=np.float64)
    launch(_inverse_kernel, blocks_for(mass.shape[0]), THREADS, mass, made)
    return made


def advance_on_device(state, new_state, u: np.ndarray, dt: float) -> None:
    """Make new_state's position x + dx, velocity dx / dt and angular velocity dth / dt on the device
    (:func:`colsim.engine.stepper.advance`'s arithmetic) from the increments' device copy, and keep
    them as its arrays' copies. Nothing to make where the increments have none (a solve on the CPU)."""
    increments = kept_device_copy(u)
    if increments is None or state.n == 0:
        return
    made = cuda.device_array((3, state.n, 3), dtype=np.float64)
    launch(_advance_kernel, blocks_for(state.n), THREADS, particle_array_on_device(state.position), increments,
           float(dt), made[0], made[1], made[2])
    for name, index in (("position", 0), ("velocity", 1), ("angular_velocity", 2)):
        frozen(getattr(new_state, name), made[index])


def predicted_on_device(state, predicted: np.ndarray, dt: float, gravity) -> None:
    """Make :func:`colsim.engine.stepper.predicted_displacement` v dt + g dt^2 (n, 3) on the device
    from the velocities' device copy, in its arithmetic, and keep it as the copy of `predicted`."""
    if state.n == 0:
        return
    made = cuda.device_array((state.n, 3), dtype=np.float64)
    blocks = blocks_for(state.n)
    # v dt, rounded: stored
    launch(_scaled_kernel, blocks, THREADS, particle_array_on_device(state.velocity), float(dt), made)
    drop = np.asarray(gravity, dtype=float) * dt**2
    launch(_shifted_kernel, blocks, THREADS, made, float(drop[0]), float(drop[1]), float(drop[2]))
    frozen(predicted, made)


def midpoints_on_device(position, predicted):
    """(n, 3) x + u/2 on the device from the device arrays `position` and `predicted` (u/2 is exact,
    so a fused multiply-add rounds it as the host does)."""
    made = cuda.device_array(position.shape, dtype=np.float64)
    launch(_midpoint_kernel, blocks_for(position.shape[0]), THREADS, position, predicted, made)
    return made


@cuda.jit
def _weight_kernel(mass, g0, g1, g2, weight):
    """weight[i] = mass[i] (g0, g1, g2), one thread a particle."""
    i = cuda.grid(1)
    if i < mass.shape[0]:
        weight[i, 0] = mass[i] * g0
        weight[i, 1] = mass[i] * g1
        weight[i, 2] = mass[i] * g2


@cuda.jit
def _program_kernel(mass, inertia, weight, velocity, angular, dt, dt2, mbar, fbar):
    """Particle i's entries of Mbar (mass / dt2, inertia / dt2) and of fbar (mass v / dt + weight,
    inertia w / dt), one thread a particle; the sum's other term is a division, never fused."""
    i = cuda.grid(1)
    n = mass.shape[0]
    if i < n:
        for d in range(3):
            mbar[3 * i + d] = mass[i] / dt2
            mbar[3 * n + 3 * i + d] = inertia[i] / dt2
            fbar[3 * i + d] = mass[i] * velocity[i, d] / dt + weight[i, d]
            fbar[3 * n + 3 * i + d] = inertia[i] * angular[i, d] / dt


@cuda.jit
def _increments_kernel(fbar, hx, mass, u):
    """u[k] = (fbar[k] + hx[k]) / mass[k], one thread an unknown."""
    k = cuda.grid(1)
    if k < u.shape[0]:
        u[k] = (fbar[k] + hx[k]) / mass[k]


@cuda.jit
def _inverse_kernel(mass, out):
    """out[k] = 1 / mass[k], one thread an unknown."""
    k = cuda.grid(1)
    if k < out.shape[0]:
        out[k] = 1.0 / mass[k]


@cuda.jit
def _advance_kernel(position, u, dt, new_position, velocity, angular):
    """Particle i's new position x + dx, velocity dx / dt and angular velocity dth / dt from u
    (6n,) = [dx; dth], one thread a particle."""
    i = cuda.grid(1)
    n = position.shape[0]
    if i < n:
        for d in range(3):
            dx = u[3 * i + d]
            new_position[i, d] = position[i, d] + dx
            velocity[i, d] = dx / dt
            angular[i, d] = u[3 * n + 3 * i + d] / dt


@cuda.jit
def _scaled_kernel(velocity, dt, out):
    """out = velocity dt (n, 3), one thread a particle."""
    i = cuda.grid(1)
    if i < velocity.shape[0]:
        for d in range(3):
            out[i, d] = velocity[i, d] * dt


@cuda.jit
def _shifted_kernel(out, s0, s1, s2):
    """out[i] += (s0, s1, s2), one thread a particle (a kernel apart from the product it adds to)."""
    i = cuda.grid(1)
    if i < out.shape[0]:
        out[i, 0] += s0
        out[i, 1] += s1
        out[i, 2] += s2


@cuda.jit
def _midpoint_kernel(position, predicted, out):
    """out = position + 0.5 predicted (n, 3), one thread a particle."""
    i = cuda.grid(1)
    if i < position.shape[0]:
        for d in range(3):
            out[i, d] = position[i, d] + 0.5 * predicted[i, d]
