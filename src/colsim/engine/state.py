"""Particle state, walls and contact laws: the data every other module reads.

Units are those of the input: lengths in the particles' length unit (the paper's diameters are
0.25-0.5), density 1 by default, gravity in length/time^2. Nothing here depends on a unit system.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

#: Contact families, used to pick friction coefficients per contact: a ContactLaw's (particle, floor,
#: wall) coefficients. The wall family is the cylinder's, and a channel's plane walls take its
#: coefficients too; each plane p has a family of its own, PLANE + p (:func:`law_family`), so that a
#: sphere in a corner touches two walls that a warm start tells apart (:func:`pair_keys`).
PARTICLE, FLOOR, CYLINDER = 0, 1, 2
#: the family of a Walls' first plane; plane p's is PLANE + p
PLANE = 3
#: the most planes a Walls holds: the wall codes of a pair key are 8 (:func:`pair_keys`)
MOST_PLANES = 5


def law_family(family):
    """The ContactLaw entry of each contact family (array or scalar): a plane's is the wall's (CYLINDER)."""
    return np.minimum(family, CYLINDER)


@dataclass
class ParticleState:
    """Spheres and their motion.

    position: (n, 3) float, length
    velocity: (n, 3) float, length/time
    angular_velocity: (n, 3) float, rad/time
    radius: (n,) float, length
    density: float, mass/length^3 (the paper: 1)
    time: float, time elapsed since the start of the run
    """

    position: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    radius: np.ndarray
    density: float = 1.0
    time: float = 0.0

    def __post_init__(self):
        self.position = _contiguous(self.position, (-1, 3))
        n = len(self.position)
        self.velocity = _contiguous(self.velocity, (n, 3))
        self.angular_velocity = _contiguous(self.angular_velocity, (n, 3))
        self.radius = _contiguous(self.radius, (n,))
        if n and np.any(self.radius <= 0):
            raise ValueError("every particle radius must be positive")
        if self.density <= 0:
            raise ValueError(f"density must be positive, got {self.density}")

    @classmethod
    def at_rest(cls, position, radius, density=1.0) -> "ParticleState":
        """Spheres at the given places with zero velocities."""
        position = np.asarray(position, dtype=float).reshape(-1, 3)
        zeros = np.zeros_like(position)
        return cls(position, zeros, zeros.copy(), radius, density)

    @property
    def n(self) -> int:
        return len(self.radius)

    @property
    def mass(self) -> np.ndarray:
        """(n,) mass = density 4/3 pi R^3."""
        return self.density * 4.0 / 3.0 * np.pi * self.radius**3

    @property
    def inertia(self) -> np.ndarray:
        """(n,) moment of inertia of a solid sphere, 2/5 m R^2."""
        return self.mass_and_inertia()[1]

    def mass_and_inertia(self) -> tuple[np.ndarray, np.ndarray]:
        """(:attr:`mass`, :attr:`inertia`), the masses made once."""
        mass = self.mass
        return mass, 0.4 * mass * self.radius**2

    def kinetic_energy(self) -> tuple[float, float]:
        """(translational, rotational) kinetic energy, mass length^2/time^2."""
        mass, inertia = self.mass_and_inertia()
        trans = 0.5 * float(np.sum(mass * np.einsum("ij,ij->i", self.velocity, self.velocity)))
        w = self.angular_velocity
        rot = 0.5 * float(np.sum(inertia * np.einsum("ij,ij->i", w, w)))
        return trans, rot

    def subset(self, keep: np.ndarray) -> "ParticleState":
        """A new state with the particles selected by a boolean mask or index array."""
        return replace(
            self,
            position=self.position[keep].copy(),
            velocity=self.velocity[keep].copy(),
            angular_velocity=self.angular_velocity[keep].copy(),
            radius=self.radius[keep].copy(),
        )

    def copy(self) -> "ParticleState":
        return self.subset(np.arange(self.n))


@dataclass(frozen=True, eq=False)
class FixedSpheres:
    """Spheres that never move and carry no unknowns: the buried part of a packing while it fills
    (:func:`colsim.stages.pack.pack`). position: (k, 3) length; radius: (k,) length.

    A contact with fixed sphere k has j = -2 - k (:func:`fixed_code`): a wall to the cone program,
    a pair to the warm start, with the particle law's friction and the lever between two spheres."""

    position: np.ndarray
    radius: np.ndarray

    def __post_init__(self):
        position = np.ascontiguousarray(self.position, dtype=float).reshape(-1, 3)
        radius = np.ascontiguousarray(self.radius, dtype=float).reshape(len(position))
        if np.any(radius <= 0):
            raise ValueError("every fixed sphere's radius must be positive")
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "radius", radius)

    @property
    def n(self) -> int:
        return len(self.radius)


def _contiguous(array, shape: tuple) -> np.ndarray:
    """`array` as a contiguous float64 array of `shape` (-1: any length): the same object when it is
    one already, so that a state made from another (dataclasses.replace) shares its unchanged arrays,
    and their device copies (:func:`colsim.engine.cuda_operator.device_copy_of`: the radii)."""
    array = np.ascontiguousarray(array, dtype=float)
    reshaped = array.reshape(shape)
    return array if reshaped.shape == array.shape else reshaped


def fixed_code(k: np.ndarray) -> np.ndarray:
    """The body index j = -2 - k of a contact with fixed sphere k (and back: k = -2 - j)."""
    return -2 - np.asarray(k, dtype=np.int64)


#: the pair keys' codes of the other body from here on: walls, then fixed spheres (:func:`pair_keys`)
OTHER_BODIES = 1 << 31


def pair_keys(i, j, family) -> np.ndarray:
    """(m,) int64: one number for each contact's pair of bodies, particle i and its other body j
    (a particle, a wall of `family`, or fixed sphere -2 - j), the same whatever the number of
    particles; i, j and the fixed spheres' k below 2^31 - 8."""
    j = np.asarray(j, dtype=np.int64)
    other = np.where(j >= 0, j, np.where(j == -1, OTHER_BODIES + np.asarray(family, dtype=np.int64),
                                         OTHER_BODIES + 8 + fixed_code(j)))
    return np.asarray(i, dtype=np.int64) * (1 << 32) + other


def pair_key(i, j, family):
    """:func:`pair_keys` of one contact (scalar code: the GPU's detection compiles it with numba.cuda,
    :mod:`colsim.engine.cuda_contacts`; a test holds the two equal for every kind of body)."""
    if j >= 0:
        other = j
    elif j == -1:
        other = OTHER_BODIES + family
    else:
        other = OTHER_BODIES + 8 + (-2 - j)
    return i * (1 << 32) + other


@dataclass(frozen=True)
class Walls:
    """Bodies that never move: the floor z = 0 and, optionally, the inside of a vertical cylinder,
    plane walls and a set of fixed spheres.

    cylinder_radius: radius r0 of the cylinder about the z axis (length), or None when it is removed.
    planes: plane walls, each (n_x, n_y, n_z, offset): the spheres stay in the half-space
        n . x >= offset + R, n a unit normal into it (offset: length); at most MOST_PLANES. Plane p's
        contacts have family PLANE + p, the lever R_i and the law's wall coefficients.
    fixed: spheres that never move (:class:`FixedSpheres`), or None.
    """

    floor: bool = True
    cylinder_radius: float | None = None
    fixed: FixedSpheres | None = None
    planes: tuple = ()

    def __post_init__(self):
        planes = tuple(tuple(float(v) for v in plane) for plane in self.planes)
        if len(planes) > MOST_PLANES or any(len(plane) != 4 for plane in planes):
            raise ValueError(f"walls take at most {MOST_PLANES} planes of 4 numbers (n_x, n_y, n_z, offset), "
                             f"got {planes}")
        for plane in planes:
            if not (np.all(np.isfinite(plane)) and abs(np.linalg.norm(plane[:3]) - 1.0) < 1e-12):
                raise ValueError(f"a plane wall needs a finite unit normal and offset, got {plane}")
        object.__setattr__(self, "planes", planes)

    def plane_array(self) -> np.ndarray:
        """(p, 4) the planes' (n_x, n_y, n_z, offset), p = 0 without planes."""
        return np.array(self.planes, dtype=float).reshape(-1, 4)


def channel_planes(length: float, width: float, gate: bool) -> tuple:
    """The plane walls of a channel along +x (:class:`Walls`' planes): the back wall x = 0, the
    sidewalls y = -width/2 and y = +width/2 and, with `gate`, the gate x = length that holds the box
    0 < x < length while it fills (length, width: length units)."""
    half = 0.5 * width
    planes = ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, -half), (0.0, -1.0, 0.0, -half))
    return planes + (((-1.0, 0.0, 0.0, -length),) if gate else ())


@dataclass(frozen=True)
class ContactLaw:
    """Sliding (mu) and rolling (mu_r) coefficients for each contact family, and the rolling lever.

    Each tuple is (particle-particle, particle-floor, particle-wall): the wall's are the cylinder's and
    a channel's plane walls' (:func:`law_family`). The paper uses
    mu = mu_r = 0 while filling and mu = 0.577, mu_r = 0.12 for the collapse; its cylinder is frictionless.
    rolling_lever: the lever arm L of the rolling moment L r between two spheres (:func:`rolling_lever`):
    "paper" (its Eqs. 6 and 9) or "effective" (R_eff, the common DEM convention).
    """

    mu: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mu_r: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rolling_lever: str = "paper"

    def __post_init__(self):
        if self.rolling_lever not in ROLLING_LEVERS:
            raise ValueError(f"rolling_lever must be one of {', '.join(ROLLING_LEVERS)}, got {self.rolling_lever!r}")
        for name in ("mu", "mu_r"):
            values = tuple(float(v) for v in getattr(self, name))
            if len(values) != 3:
                raise ValueError(f"{name} needs 3 values (particle, floor, wall), got {values}")
            if any(v < 0 or not np.isfinite(v) for v in values):
                raise ValueError(f"friction coefficient {name} must be finite and >= 0, got {values}")
            object.__setattr__(self, name, values)

    @classmethod
    def uniform(cls, mu: float, mu_r: float, cylinder_mu: float = 0.0,
                rolling_lever: str = "paper") -> "ContactLaw":
        """The same mu, mu_r on particles and floor; a frictionless cylinder (as in the paper)."""
        return cls(mu=(mu, mu, cylinder_mu), mu_r=(mu_r, mu_r, 0.0), rolling_lever=rolling_lever)


# The lever arm of the rolling moment between two spheres (SPEC section 2, "Rolling"). The paper's
# Eq. (6) turns the rolling force r into each particle's moment through the particle-radius matrix R,
# as it does the friction force, and its Eq. (9) gives a disc's resisting moment as mu_r r p, r the
# disc's own radius: between spheres L = 2 R_i R_j / (R_i + R_j), each radius when they are equal.
# "effective": R_eff = R_i R_j / (R_i + R_j), half of it between equal spheres. At a wall both are R_i.
ROLLING_LEVERS = ("paper", "effective")
#: the lever of the files written before the option existed (colsim used R_eff then; docs/validation/rolling-lever.md)
LEVER_OF_OLDER_FILES = "effective"


def rolling_lever(radius_i: np.ndarray, radius_j: np.ndarray, lever: str = "paper") -> np.ndarray:
    """Lever arm L (length) of each contact's rolling moment L r; radius_j = 0 marks a wall (L = R_i).

    radius_i, radius_j: (m,) radii (length); lever: one of ROLLING_LEVERS."""
    if lever not in ROLLING_LEVERS:
        raise ValueError(f"rolling lever must be one of {', '.join(ROLLING_LEVERS)}, got {lever!r}")
    radius_i, radius_j = np.asarray(radius_i, dtype=float), np.asarray(radius_j, dtype=float)
    between = radius_i * radius_j / np.where(radius_j > 0, radius_i + radius_j, 1.0)
    scale = 2.0 if lever == "paper" else 1.0
    return np.where(radius_j > 0, scale * between, radius_i)


FRICTION_LAWS = ("associated", "coulomb")


@dataclass(frozen=True)
class FrictionLaw:
    """The friction law of the contacts (:mod:`colsim.engine.friction`): name 'associated' (the paper's) or
    'coulomb'; for coulomb, the fixed point's tolerance (a fraction of the mean diameter) and the
    most cone programs solved per step (max_iter)."""

    name: str = "associated"
    tolerance: float = 1e-5
    max_iter: int = 100

    def __post_init__(self):
        if self.name not in FRICTION_LAWS:
            raise ValueError(f"friction law must be one of {', '.join(FRICTION_LAWS)}, got {self.name!r}")
        if not self.tolerance > 0 or self.max_iter < 1:
            raise ValueError(f"the Coulomb fixed point needs tolerance > 0 and max_iter >= 1, got "
                             f"{self.tolerance}, {self.max_iter}")


@dataclass(frozen=True)
class StepSettings:
    """Everything one time step needs besides the state.

    dt: time step (time). gravity: (3,) acceleration (length/time^2), -z by default.
    overlap_tolerance: largest overlap accepted after a step, as a fraction of the smallest diameter.
    detection_margin_fraction: gap beyond the predicted motion within which a pair is a potential
    contact, as a fraction of the smallest diameter (the stepper's margins are lengths). detection_slack: fraction of a pair's predicted relative
    displacement added to that margin (see :func:`colsim.engine.contacts.detect`).
    friction: the friction law, associated (the paper's) or coulomb (:mod:`colsim.engine.friction`).
    max_redo: how many times a step with a missed contact is redone (see :mod:`colsim.engine.stepper`).
    margin_growth: factor by which a redone step's detection margin grows.
    overlap_recovery: the most speed at which an overlap present at the start of a step is removed,
    as a fraction of sqrt(|g| d), d the mean diameter (:func:`recovery_speed`); None removes it
    within one step, whatever the step (a speed of overlap/dt, which grows as dt shrinks).
    overlap_kept: an overlap present at the start of a step up to this fraction of the smallest
    diameter is kept (it never grows) and not asked back; a larger one shrinks towards it
    (:func:`colsim.engine.contacts.recovery_relaxation`). 0: every overlap is asked back. A channel's
    collapse keeps half the overlap tolerance: between its sidewalls a chain of grains from wall to wall
    may have no motion but dilating ones, and asking its overlap back leaves the step no solution.
    """

    dt: float
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    walls: Walls = field(default_factory=Walls)
    law: ContactLaw = field(default_factory=ContactLaw)
    friction: FrictionLaw = field(default_factory=FrictionLaw)
    overlap_tolerance: float = 0.01
    detection_margin_fraction: float = 0.05
    detection_slack: float = 0.5
    max_redo: int = 4
    margin_growth: float = 2.0
    overlap_recovery: float | None = 0.01
    overlap_kept: float = 0.0

    def __post_init__(self):
        if not (self.dt > 0 and np.isfinite(self.dt)):
            raise ValueError(f"time step dt must be positive, got {self.dt}")
        if self.margin_growth <= 1:
            raise ValueError(f"margin_growth must be > 1, got {self.margin_growth}")
        if self.overlap_tolerance <= 0 or self.detection_margin_fraction < 0 or self.detection_slack < 0:
            raise ValueError("overlap_tolerance must be > 0, detection_margin_fraction and detection_slack >= 0")
        if self.overlap_recovery is not None and not (self.overlap_recovery > 0 and np.isfinite(self.overlap_recovery)):
            raise ValueError(f"overlap_recovery must be a positive finite fraction or None, got {self.overlap_recovery}")
        if not 0.0 <= self.overlap_kept < self.overlap_tolerance:
            raise ValueError(f"overlap_kept must lie in [0, overlap_tolerance {self.overlap_tolerance}), got "
                             f"{self.overlap_kept}")
        if self.walls.cylinder_radius is not None and self.walls.cylinder_radius <= 0:
            raise ValueError(f"cylinder radius must be positive, got {self.walls.cylinder_radius}")


def recovery_speed(settings: StepSettings, mean_diameter: float) -> float:
    """The most speed (length/time) at which a step removes an overlap it starts with:
    overlap_recovery sqrt(|g| d), inf without a cap. At 0.01 a sphere recovering an overlap carries
    at most 5e-5 m g d of kinetic energy, 20 times below the packing's rest threshold (1e-3 m g d)."""
    if settings.overlap_recovery is None:
        return np.inf
    return settings.overlap_recovery * float(np.sqrt(np.linalg.norm(settings.gravity) * mean_diameter))
