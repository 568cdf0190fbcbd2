"""How often the calibration's intervals hold the truth: synthetic studies whose limits are known,
some of them breaking what the fit assumes.

A synthetic study has the calibration's design (mu_r = 0.06, 0.12, 0.2, 0.3; a = 0.5-5; r0 = 2, 3, 4;
three seeds) and known large-column limits: Lube's laws, reached by aspect ratio a at its own mu_r
(WANTED_MU_R, the values the measured calibration found per a, so that no one mu_r fits every a, as
measured), heights rising 1.5 and run-outs falling 2 relative per unit of mu_r about it. A run falls
short of its limit by a finite-size term and scatters by seed noise:

    X(r0, seed) = X_inf (1 - c (d/r0)^p) (1 + sigma e),   c = 0.8 (d/3)^(1 - p),

so that every exponent p gives the same shortfall at r0 = 3 (0.8 d/r0 there, as measured), and sigma
the measured seed noise (MEASURED_NOISE). The cases (CASES) change one thing each: the exponent p,
curvature in mu_r (the limits saturating, as the measured heights do from mu_r = 0.2 on), noise
shared by every run of a packing (every a and mu_r poured from it), and more noise.

coverage() runs `calibrate` on many such studies and counts how often each interval holds the true
value: of every limit, of the best mu_r (Lube, both measures) and of the minimax mu_r (Lube), the
true ones found on the true limits' own curves (no interpolation).

The column-size study's limits (colsim.study.size_limit) are measured the same way on studies of
that study's design (SIZE_DESIGN, config/column-size.yaml: r0 = 2-4 with three seeds and r0 = 5-6
with two, at a = 0.5-5, mu_r = 0.12; a = 3 and 4 up to r0 = 5 only): the true limits are Lube's laws
at each a, reached as above, and size_coverage() counts how often each limit's interval holds its
true value (SIZE_CASES: the exponent p and the noise).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .calibration import Runs, calibrate, misfits, relative_errors
from .convergence import SIZE_EXPONENTS
from .experimental_laws import lube_height, lube_runout
from .size_limit import size_limit

MU_R = np.array([0.06, 0.12, 0.2, 0.3])
RATIOS = np.array([0.5, 1, 2, 3, 4, 5])
RADII = np.array([2.0, 3.0, 4.0])
SEEDS = 3
DIAMETER = 0.375                        #: mean particle diameter, as in the study's packings
#: the mu_r each a wants (the measured calibration's per-a best, docs/validation/calibration.md)
WANTED_MU_R = np.array([0.126, 0.071, 0.124, 0.174, 0.252, 0.216])
SLOPES = (1.5, -2.0)                    #: relative change of the height and run-out limits per unit mu_r
#: seed noise (relative standard deviation of one run) of the heights and run-outs: the median over
#: the measured limits of their interval's half-width / (1.96 x 1.205 x limit), 1.205 the standard
#: error of a p = 1 limit from r0 = 2, 3, 4 with three seeds each, per unit of a run's noise
#: (docs/data/calibration_limits.csv)
MEASURED_NOISE = (0.027, 0.038)
SATURATION = 0.08                       #: mu_r scale of the curved case's saturation


@dataclass(frozen=True)
class Case:
    """One kind of synthetic study: the size law's exponent, whether the limits curve in mu_r, the
    share of the noise's variance shared by a packing's runs, and the noise over the measured."""
    name: str
    exponent: float = 1.0
    curved: bool = False
    shared: float = 0.0
    noise: float = 1.0


CASES = (Case("as the fit assumes"), Case("exponent p = 0.5", exponent=0.5), Case("exponent p = 1.5", exponent=1.5),
         Case("curved in mu_r", curved=True), Case("noise shared by a packing (70 %)", shared=0.7),
         Case("noise 2x", noise=2.0), Case("noise 4x", noise=4.0))


def true_limits(mu_r, curved: bool = False) -> np.ndarray:
    """(2, n_mu, n_a) the true limits at mu_r: Lube's laws at each a's WANTED_MU_R, changing by SLOPES
    per unit mu_r about it, linearly or (curved) saturating on the scale SATURATION."""
    shift = np.asarray(mu_r, dtype=float)[:, None] - WANTED_MU_R[None, :]
    if curved:
        shift = SATURATION * (1 - np.exp(-shift / SATURATION))
    laws = (lube_height(RATIOS), lube_runout(RATIOS))
    return np.stack([law[None, :] * (1 + slope * shift) for law, slope in zip(laws, SLOPES)])


def synthetic_study(case: Case, rng: np.random.Generator) -> Runs:
    """One study's runs under `case` (module docstring)."""
    limits = true_limits(MU_R, case.curved)
    p = case.exponent
    shortfall = 0.8 * (DIAMETER / 3.0) ** (1 - p) * (DIAMETER / RADII) ** p          # (n_r,)
    shape = (2, len(MU_R), len(RATIOS), len(RADII), SEEDS)
    packing = rng.standard_normal((2, 1, 1, len(RADII), SEEDS))
    own = rng.standard_normal(shape)
    e = np.sqrt(case.shared) * packing + np.sqrt(1 - case.shared) * own
    sigma = case.noise * np.array(MEASURED_NOISE)[:, None, None, None, None]
    values = limits[..., None, None] * (1 - shortfall[:, None]) * (1 + sigma * e)
    grids = np.meshgrid(MU_R, RATIOS, RADII, np.arange(1, SEEDS + 1), indexing="ij")
    mu_r, a, r0, seed = (g.ravel() for g in grids)
    return Runs(mu_r, a, r0, seed, DIAMETER / r0, values[0].ravel(), values[1].ravel())


def true_optima(curved: bool, points: int = 4001) -> tuple[float, float]:
    """(best mu_r for Lube, both measures; minimax mu_r for Lube) on the true limits' own curves over
    the sweep."""
    grid = np.linspace(MU_R[0], MU_R[-1], points)
    errors = relative_errors(true_limits(grid, curved), RATIOS, "lube")
    best = grid[np.argmin(misfits(errors)[2])]
    minimax = grid[np.argmin(np.abs(errors).max(axis=(0, 2)))]
    return float(best), float(minimax)


def coverage(case: Case, studies: int = 200, replicates: int = 400, seed: int = 2026,
             **method) -> dict:
    """{target: share of `studies` synthetic studies whose interval held the true value}, targets
    "limits" (every limit's interval, pooled), "best mu_r" and "minimax mu_r"; `method`: calibrate's
    interval options (exponents, student). Reproducible from `seed`."""
    rng = np.random.default_rng(seed)
    truth = true_limits(MU_R, case.curved)
    best, minimax = true_optima(case.curved)
    held = {"limits": 0.0, "best mu_r": 0, "minimax mu_r": 0}
    for k in range(studies):
        result = calibrate(synthetic_study(case, rng), replicates=replicates, seed=k, **method)
        for q, name in enumerate(("height", "runout")):
            held["limits"] += np.mean((result[f"{name}_low"].values <= truth[q])
                                      & (truth[q] <= result[f"{name}_high"].values)) / 2
        lube = result.sel(law="lube")
        held["best mu_r"] += float(lube.best_mu_r_low.sel(measure="both")) <= best <= float(
            lube.best_mu_r_high.sel(measure="both"))
        held["minimax mu_r"] += float(lube.minimax_mu_r_low) <= minimax <= float(lube.minimax_mu_r_high)
    return {target: float(count) / studies for target, count in held.items()}


#: the methods the coverage table compares: calibrate's interval options
METHODS = {"percentile, p = 1 (before)": {"exponents": None, "student": False},
           "p from 0.5-1.5, Student's t": {}}


def coverage_table(studies: int = 200, replicates: int = 400) -> str:
    """The coverage of every case and method (METHODS) as a Markdown table."""
    lines = ["| case | method | nominal | limits | best mu_r | minimax mu_r |", "|---|---|---|---|---|---|"]
    for case in CASES:
        for name, method in METHODS.items():
            held = coverage(case, studies, replicates, **method)
            lines.append(f"| {case.name} | {name} | 95 % | " + " | ".join(f"{100 * v:.1f} %" for v in held.values()) + " |")
    return "\n".join(lines)


#: the column-size study's design (config/column-size.yaml): a -> {r0: seeds}
SIZE_DESIGN = {a: {2.0: 3, 3.0: 3, 4.0: 3, 5.0: 2, **({} if a in (3, 4) else {6.0: 2})} for a in RATIOS}
SIZE_CASES = (Case("exponent p = 1"), Case("exponent p = 0.5", exponent=0.5), Case("exponent p = 1.5", exponent=1.5),
              Case("noise 2x", noise=2.0))


def size_study(case: Case, rng: np.random.Generator) -> dict:
    """{(measure index, a): {r0: the runs' values}} of one synthetic column-size study under `case`
    (module docstring; measure 0 the height, 1 the run-out)."""
    p, study = case.exponent, {}
    for q, law in enumerate((lube_height, lube_runout)):
        sigma = case.noise * MEASURED_NOISE[q]
        for a, sizes in SIZE_DESIGN.items():
            shortfall = {r0: 0.8 * (DIAMETER / 3.0) ** (1 - p) * (DIAMETER / r0) ** p for r0 in sizes}
            study[(q, a)] = {r0: float(law(a)) * (1 - shortfall[r0]) * (1 + sigma * rng.standard_normal(seeds))
                             for r0, seeds in sizes.items()}
    return study


def size_coverage(case: Case, studies: int = 200, replicates: int = 400, seed: int = 2026, **method) -> float:
    """The share of the limits of `studies` synthetic column-size studies (every a, height and
    run-out, pooled) whose 95 % interval held the true limit; `method`: size_limit's interval options.
    Reproducible from `seed`."""
    rng = np.random.default_rng(seed)
    held = []
    for k in range(studies):
        for (q, a), runs in size_study(case, rng).items():
            limit = size_limit(runs, DIAMETER, replicates=replicates, seed=k, fit_exponent=False, **method)
            truth = float((lube_height, lube_runout)[q](a))
            held.append(limit.low <= truth <= limit.high)
    return float(np.mean(held))


#: the methods the column-size coverage table compares: size_limit's interval options
SIZE_METHODS = {"percentile, p = 1": {"exponents": None, "student": False},
                "p from 0.5-1.5, Student's t (the calibration's)": {},
                "p from 0.3-1.6, Student's t (the column-size study's)": {"exponents": SIZE_EXPONENTS}}


def size_coverage_table(studies: int = 200, replicates: int = 400) -> str:
    """The coverage of the column-size limits for every case of SIZE_CASES and method (SIZE_METHODS)
    as a Markdown table."""
    lines = ["| case | method | nominal | limits held |", "|---|---|---|---|"]
    for case in SIZE_CASES:
        for name, method in SIZE_METHODS.items():
            lines.append(f"| {case.name} | {name} | 95 % | {100 * size_coverage(case, studies, replicates, **method):.1f} % |")
    return "\n".join(lines)


if __name__ == "__main__":
    # python -m colsim.study.coverage [studies]: the table of docs/validation/calibration.md;
    # python -m colsim.study.coverage sizes [studies]: the table of docs/validation/column-size.md
    import sys

    arguments = sys.argv[1:]
    table = size_coverage_table if arguments[:1] == ["sizes"] else coverage_table
    arguments = arguments[1:] if table is size_coverage_table else arguments
    print(table(int(arguments[0]) if arguments else 200), flush=True)
