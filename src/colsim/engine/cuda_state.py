"""The particles' arrays of a step on the GPU, made there from the last step's and left there.

A step on the GPU needs, besides the contacts, each particle's position and predicted motion (for
detection) and the program's masses and free forces (for the solver). The device makes its own from
what it holds, in the host's arithmetic:

- the program's masses (6n,) and free forces fbar (6n,), from the velocities and the particles'
  masses (copied once a run: they change only with the radii): a :class:`DeviceProgram`;
- the increments u = Mbar^-1 (fbar + B' lam) (6n,), from the solver's B' lam;
- the next state's positions, velocities and angular velocities, from the increments: a
  :class:`DeviceState`;
- the predicted motion v dt + g dt^2, from the velocities: a :class:`DeviceParticleArray`.

None of them is made on the host, nor copied there, unless something reads it there (a frame, a
checkpoint, a solver on the CPU, a redo's walls, a pour's rest test): then it is copied once, and
the copy keeps the device's array as its device copy
(:func:`colsim.engine.cuda_operator.keep_device_copy`). What a step reads of them is reduced there
(:meth:`DeviceState.measures`: the kinetic energy and the walls' largest overlaps;
:meth:`DeviceProgram.scales`: the stopping rule's lengths), a few numbers a step. So after a run's
first step no particle array goes either way.
Each array is the host's number, bit for bit: the arithmetic is additions, divisions and products,
each rounded once. A GPU fuses a product and a sum into one rounding where it can, so every product
that a sum reads is made by a kernel of its own (the weights m g, the motion v dt), or is exact (x +
u/2). The reductions' sums are taken in another order than numpy's: they differ from the host's by
rounding (a fixed order: the same every run).

A host array kept so must not change in place (its device copy would not follow): :func:`host_copy`
makes each read-only, so a change fails loudly; so are the radii, whose masses are kept. Without a
GPU the kernels run on numba's simulator (NUMBA_ENABLE_CUDASIM=1), where
tests/engine/test_cuda_state.py compares each with the host's.
"""
from __future__ import annotations

import math
import weakref

import numpy as np

from .cuda_launch import launch
from .cuda_operator import (THREADS, block_reduce, blocks_for, cuda, device_copy_of, four_block_results,
                            keep_device_copy, kept_device_copy)
from .program import ConeProgram
from .state import ParticleState

#: the particles' masses, inertias and weights on the device, by the identity of their radii's host
#: array (a state made from another by dataclasses.replace shares it), then by density (the masses
#: and inertias) or by (density, gravity) (the weights)
_particles: dict = {}

#: the fields of a particle state that a step makes on the device
MOVING = ("position", "velocity", "angular_velocity")


def host_copy(on_device, read_only: bool = True) -> np.ndarray:
    """The host's copy of a device array, which keeps the device's as its copy; read-only unless told
    (a change in place would not reach the device's)."""
    host = on_device.copy_to_host()
    keep_device_copy(host, on_device)
    host.flags.writeable = not read_only
    return host


def particle_array_on_device(array):
    """The device copy of a particle array (a state's, a predicted motion): a
    :class:`DeviceParticleArray`'s own, the one kept, or one made now from the host's (a run's
    first step; the array is then read-only, as a :func:`host_copy` is)."""
    if isinstance(array, DeviceParticleArray):
        return array.on_device
    kept = kept_device_copy(array)
    if kept is None:
        kept = device_copy_of(array)
        array.flags.writeable = False
    return kept


def state_array_on_device(state, name: str):
    """The device array of the field `name` ('position', 'velocity', 'angular_velocity') of a
    particle state: a :class:`DeviceState`'s own (no copy either way), else the host array's."""
    arrays = getattr(state, "_arrays", None)
    if arrays is not None:
        return arrays[name]
    return particle_array_on_device(getattr(state, name))


class DeviceParticleArray:
    """An (n, 3) particle array made on the device (a predicted motion, length): `on_device`, and the
    host's copy, made when first asked for (``np.asarray``; read-only, keeping the device's)."""

    def __init__(self, on_device):
        self.on_device = on_device
        self._host = None

    def __array__(self, dtype=None, copy=None):
        if self._host is None:
            self._host = host_copy(self.on_device)
        return self._host.astype(dtype or self._host.dtype, copy=bool(copy))


class DeviceState(ParticleState):
    """A :class:`colsim.engine.state.ParticleState` made by a step on the GPU: its positions,
    velocities and angular velocities are on the device (`_arrays`, by name), and each is copied to
    the host when first read there (a frame, a checkpoint, a pour's rest test, a redo's walls); the
    copy keeps the device's array as its own, read-only. The radii, density and time are the host's.
    Its kinetic energy and the walls' largest overlaps are measured on the device (:meth:`measures`).
    A state made from it by dataclasses.replace (a copy, a subset) is an ordinary one, on the host."""

    _arrays = None     # {name: device array} of a state made on the device
    _measured = None   # its measures, once made

    @classmethod
    def made_on_device(cls, like: ParticleState, arrays: dict, time: float) -> "DeviceState":
        """The state of `like`'s particles (radii, density) at `time` with the device arrays `arrays`
        (:data:`MOVING`, each (n, 3))."""
        state = object.__new__(cls)
        state.radius, state.density, state.time = like.radius, like.density, time
        state._arrays = arrays
        return state

    def __getattr__(self, name):   # only for an attribute not set: a field still on the device
        arrays = self.__dict__.get("_arrays")
        if arrays is None or name not in arrays:
            raise AttributeError(name)
        host = host_copy(arrays[name])
        setattr(self, name, host)
        return host

    def kinetic_energy(self) -> tuple[float, float]:
        """(translational, rotational) kinetic energy (mass length^2/time^2), summed on the device."""
        if self._arrays is None:
            return super().kinetic_energy()
        trans, rot, _, _ = self.measures()
        return trans, rot

    def measures(self) -> tuple[float, float, float, float]:
        """(translational and rotational kinetic energy, the largest R_i - z_i (the floor's overlap
        where positive), the largest rho_i + R_i (rho_i the distance from the z axis; the cylinder's
        overlap where it exceeds the cylinder's radius)), lengths and mass length^2/time^2, measured
        on the device once (:func:`_measures_kernel`), one copy of the blocks' parts to the host,
        summed there in block order."""
        if self._measured is None:
            mass, inertia = particle_masses_on_device(self)
            n = self.n
            parts = cuda.device_array((4, blocks_for(n)), dtype=np.float64)
            launch(_measures_kernel, blocks_for(n), THREADS, *(self._arrays[name] for name in MOVING),
                   particle_array_on_device(self.radius), mass, inertia, parts)
            trans, rot, floor, cylinder = parts.copy_to_host()
            self._measured = (0.5 * float(np.sum(trans)), 0.5 * float(np.sum(rot)), float(floor.max()),
                              float(cylinder.max()))
        return self._measured


def measured_on_device(state):
    """:meth:`DeviceState.measures` of a state made on the device with particles, else None."""
    if getattr(state, "_arrays", None) is None or state.n == 0:
        return None
    return state.measures()


def _setting(state, key):
    """The device arrays kept for the radii of `state` under `key` (None: none yet) and their dict."""
    by_setting = _particles.get(id(state.radius))
    if by_setting is None:
        by_setting = _particles[id(state.radius)] = {}
        weakref.finalize(state.radius, _particles.pop, id(state.radius), None)
    return by_setting.get(key), by_setting


def particle_masses_on_device(state) -> tuple:
    """(mass (n,), inertia (n,)) of the particles of `state` on the device, copied once for their
    radii and density."""
    key = float(state.density)
    kept, by_setting = _setting(state, key)
    if kept is None:
        state.radius.flags.writeable = False   # the masses kept follow from these radii
        both = cuda.to_device(np.stack(state.mass_and_inertia()))
        kept = by_setting[key] = (both[0], both[1])
    return kept


def masses_on_device(state, gravity) -> tuple:
    """(mass (n,), inertia (n,), weight m g (n, 3)) of the particles of `state` on the device: the
    first two by :func:`particle_masses_on_device`, the weights made there (products alone) once
    for their radii, density and gravity."""
    mass, inertia = particle_masses_on_device(state)
    key = (float(state.density), tuple(float(g) for g in gravity))
    weight, by_setting = _setting(state, key)
    if weight is None:
        weight = by_setting[key] = cuda.device_array((state.n, 3), dtype=np.float64)
        launch(_weight_kernel, blocks_for(state.n), THREADS, mass, *key[1], weight)
    return mass, inertia, weight


class DeviceProgram(ConeProgram):
    """A :class:`colsim.engine.program.ConeProgram` of n > 0 particles whose masses and free forces were
    made on the device (`_made` (2, 6n): mass, fbar) and stay there until read on the host (a solver on the
    CPU, a Coulomb fixed point's next program): then copied once, keeping the device's as their copy.
    The stopping rule's lengths are measured there (:meth:`scales`). A program made from it by
    dataclasses.replace is an ordinary one."""

    _made = None       # (2, 6n) device array of a program made on the device
    _scales = None     # its scales, once measured

    @classmethod
    def made_on_device(cls, made, contacts) -> "DeviceProgram":
        program = object.__new__(cls)
        program.contacts, program.gap_shift, program.matrix, program._operator = contacts, None, None, None
        program._made = made
        return program

    def __getattr__(self, name):   # only for an attribute not set: mass or fbar, still on the device
        made = self.__dict__.get("_made")
        if made is None or name not in ("mass", "fbar"):
            raise AttributeError(name)
        host = host_copy(made[0 if name == "mass" else 1])
        setattr(self, name, host)
        return host

    @property
    def n_unknowns(self) -> int:
        return self._made.shape[1] if self._made is not None else len(self.mass)

    def scales(self) -> tuple[float, float, float]:
        """(the root-mean-square free-flight displacement, the mean diameter, the mean particle mass
        over dt^2) of :mod:`colsim.engine.cones`, measured on the device once (the host's arithmetic
        for each particle; the sums in block order)."""
        if self._scales is None:
            n = self.n_unknowns // 6
            parts = cuda.device_array((3, blocks_for(n)), dtype=np.float64)
            launch(_program_scales_kernel, blocks_for(n), THREADS, self._made[0], self._made[1], parts)
            flight, diameter, mass = (float(np.sum(row)) for row in parts.copy_to_host())
            self._scales = (float(np.sqrt(flight / n)), 2.0 * diameter / n, mass / (3 * n))
        return self._scales

    def free_flight_rms(self) -> float:
        return self.scales()[0] if self._made is not None else super().free_flight_rms()

    def mean_diameter(self) -> float:
        return self.scales()[1] if self._made is not None else super().mean_diameter()

    def mean_mass(self) -> float:
        return self.scales()[2] if self._made is not None else super().mean_mass()


def program_on_device(state, contacts, dt: float, gravity) -> DeviceProgram:
    """:func:`colsim.engine.program.assemble`'s mass (6n,) = [m; I] / dt^2 (three times each) and fbar
    (6n,) = [m v / dt + m g; I w / dt], made on the device from the velocities there, in its
    arithmetic: the program with `contacts`."""
    n = state.n
    particle_mass, inertia, weight = masses_on_device(state, gravity)
    velocity, angular = state_array_on_device(state, "velocity"), state_array_on_device(state, "angular_velocity")
    made = cuda.device_array((2, 6 * n), dtype=np.float64)
    launch(_program_kernel, blocks_for(n), THREADS, particle_mass, inertia, weight, velocity, angular, float(dt),
           float(dt) ** 2, made[0], made[1])
    return DeviceProgram.made_on_device(made, contacts)


def program_array_on_device(program, name: str):
    """The device array of a program's `name` ('mass' or 'fbar'): a :class:`DeviceProgram`'s own (no
    copy either way), else the host array's copy (made once)."""
    made = getattr(program, "_made", None)
    if made is not None:
        return made[0 if name == "mass" else 1]
    return device_copy_of(getattr(program, name))


def increments_on_device(program, hx):
    """(6n,) device array u = (fbar + hx) / mass, made from hx = B' lam there and the program's fbar
    and mass there."""
    u = cuda.device_array(program.n_unknowns, dtype=np.float64)
    launch(_increments_kernel, blocks_for(u.shape[0]), THREADS, program_array_on_device(program, "fbar"), hx,
           program_array_on_device(program, "mass"), u)
    return u


def inverses_on_device(mass):
    """1 / mass on the device, from the device array `mass` (a division: the host's bits)."""
    made = cuda.device_array(mass.shape[0], dtype=np.float64)
    launch(_inverse_kernel, blocks_for(mass.shape[0]), THREADS, mass, made)
    return made


def advance_on_device(state, u, dt: float) -> DeviceState:
    """The state after a step of dt: :func:`colsim.engine.stepper.advance`'s position x + dx,
    velocity dx / dt and angular velocity dth / dt, made on the device from the device array u (6n,)
    (its arithmetic), and left there."""
    made = cuda.device_array((3, state.n, 3), dtype=np.float64)
    launch(_advance_kernel, blocks_for(state.n), THREADS, state_array_on_device(state, "position"), u, float(dt),
           made[0], made[1], made[2])
    return DeviceState.made_on_device(state, dict(zip(MOVING, made)), state.time + dt)


def predicted_on_device(state, dt: float, gravity) -> DeviceParticleArray:
    """:func:`colsim.engine.stepper.predicted_displacement` v dt + g dt^2 (n, 3), made on the device
    from the velocities there, in its arithmetic."""
    made = cuda.device_array((state.n, 3), dtype=np.float64)
    blocks = blocks_for(state.n)
    # v dt, rounded: stored
    launch(_scaled_kernel, blocks, THREADS, state_array_on_device(state, "velocity"), float(dt), made)
    drop = np.asarray(gravity, dtype=float) * dt**2
    launch(_shifted_kernel, blocks, THREADS, made, float(drop[0]), float(drop[1]), float(drop[2]))
    return DeviceParticleArray(made)


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


@cuda.jit(device=True)
def axis_distance(position, i):
    """rho_i = sqrt(x_i^2 + y_i^2), particle i's distance from the z axis: the host's np.hypot to a unit
    or two in the last place (the card's own hypot is not glibc's either, and holds fused
    multiply-adds)."""
    return math.sqrt(position[i, 0] * position[i, 0] + position[i, 1] * position[i, 1])


@cuda.jit
def _measures_kernel(position, velocity, angular, radius, mass, inertia, parts):
    """parts[0..3] (per block of particles): the sums of m |v|^2 and I |w|^2, the largest R - z and the
    largest rho + R (rho: :func:`axis_distance`, as the walls' kernels take it), one thread a particle."""
    trans = cuda.shared.array(THREADS, dtype=np.float64)
    rot = cuda.shared.array(THREADS, dtype=np.float64)
    sunk = cuda.shared.array(THREADS, dtype=np.float64)
    out = cuda.shared.array(THREADS, dtype=np.float64)
    i = cuda.grid(1)
    t = cuda.threadIdx.x
    trans[t], rot[t], sunk[t], out[t] = 0.0, 0.0, -math.inf, -math.inf
    if i < position.shape[0]:
        v = velocity[i, 0] * velocity[i, 0] + velocity[i, 1] * velocity[i, 1] + velocity[i, 2] * velocity[i, 2]
        w = angular[i, 0] * angular[i, 0] + angular[i, 1] * angular[i, 1] + angular[i, 2] * angular[i, 2]
        trans[t] = mass[i] * v
        rot[t] = inertia[i] * w
        sunk[t] = radius[i] - position[i, 2]
        out[t] = axis_distance(position, i) + radius[i]
    four_block_results(parts, t, trans, rot, sunk, out, False, False, True, True)


@cuda.jit
def _program_scales_kernel(mbar, fbar, parts):
    """parts[0..2] (per block of particles): the sums of |v dt + g dt^2|^2 (the free flight
    fbar / mbar's translational entries), of sqrt(I / (0.4 m)) (the radii) and of mbar's three
    translational entries, one thread a particle (colsim.engine.program.ConeProgram's arithmetic)."""
    flight = cuda.shared.array(THREADS, dtype=np.float64)
    radius = cuda.shared.array(THREADS, dtype=np.float64)
    mass = cuda.shared.array(THREADS, dtype=np.float64)
    i = cuda.grid(1)
    t = cuda.threadIdx.x
    n = mbar.shape[0] // 6
    flight[t], radius[t], mass[t] = 0.0, 0.0, 0.0
    if i < n:
        square = 0.0
        total = 0.0
        for d in range(3):
            moved = fbar[3 * i + d] / mbar[3 * i + d]
            square += moved * moved
            total += mbar[3 * i + d]
        flight[t] = square
        radius[t] = math.sqrt(mbar[3 * n + 3 * i] / (0.4 * mbar[3 * i]))
        mass[t] = total
    block_reduce(flight, t, False)
    block_reduce(radius, t, False)
    block_reduce(mass, t, False)
    if t == 0:
        b = cuda.blockIdx.x
        parts[0, b], parts[1, b], parts[2, b] = flight[0], radius[0], mass[0]
