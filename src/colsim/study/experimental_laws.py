"""Experimental scaling laws of the final deposit: the axisymmetric ones (SPEC section 5; the
paper's Eqs. 1-4) and the quasi-two-dimensional (channel) ones.

Every function takes the aspect ratio a = h0 / r0 (scalar or array, dimensionless) and returns a
float or an array of the same shape: the run-out (r_inf - r0) / r0 or the final height h_inf / r0.
The laws were measured for 0 <= a < 10; outside that range (and for NaN input) they return NaN.
In a channel, r0 is the box length L0 (the column's extent from the back wall), a = H0 / L0, the
run-out is (L_inf - L0) / L0 and the height H_inf / L0 (the analysis stores them under the same
names, colsim.stages.analyse).

Axisymmetric (cylinder):

- Lube et al. (2004): run-out 1.24 a (a < 1.7), 1.6 a^0.5 (1.7 <= a < 10);
  height a (a < 1), 0.88 a^(1/6) (1 <= a < 10).
- Lajeunesse et al. (2004): run-out 1.35 a (a < 0.74), 2.0 a^0.5 (0.74 <= a < 10);
  height a (a < 0.74), 0.74 a (a >= 0.74).

The Lajeunesse height law is kept exactly as the paper prints it (its Eq. 4). As printed it jumps at
a = 0.74 (from 0.74 to 0.548); it is drawn as printed and the jump is left visible.

Quasi-two-dimensional (channel): see the section "Channel laws" below, where each law states its
source. The primary papers' full texts were not available to colsim's authors: each coefficient is
taken from the best source found and the source is named. The secondary sources disagree on
coefficients and break points; the disagreements are listed with each law.
"""
from __future__ import annotations

import numpy as np

LUBE_RUNOUT_BREAK = 1.7
LUBE_HEIGHT_BREAK = 1.0
LAJEUNESSE_BREAK = 0.74
LARGEST_ASPECT_RATIO = 10.0

__all__ = ["lube_runout", "lube_height", "lajeunesse_runout", "lajeunesse_height", "LAWS",
           "lube_2005_runout", "lube_2005_height", "lajeunesse_2005_runout", "lajeunesse_2005_height",
           "CHANNEL_LAWS", "BALMFORTH_KERSWELL", "laws_for", "power_law_exponent"]


def _piecewise(a, brk, below, above, above_from=None):
    """below(a) for 0 <= a < brk, above(a) for `above_from` (default brk) <= a < 10, NaN elsewhere
    (between brk and above_from too, where a law's authors give no value); scalar in, float out."""
    above_from = brk if above_from is None else above_from
    values = np.asarray(a, dtype=float)
    with np.errstate(invalid="ignore"):
        safe = np.where(values >= 0, values, 0.0)
        result = np.where(values < brk, below(safe), np.where(values >= above_from, above(safe), np.nan))
        result = np.where((values >= 0) & (values < LARGEST_ASPECT_RATIO), result, np.nan)
    return float(result) if result.ndim == 0 else result


def lube_runout(a):
    """(r_inf - r0) / r0 of Lube et al. (2004): 1.24 a below a = 1.7, 1.6 a^0.5 above."""
    return _piecewise(a, LUBE_RUNOUT_BREAK, lambda x: 1.24 * x, lambda x: 1.6 * np.sqrt(x))


def lube_height(a):
    """h_inf / r0 of Lube et al. (2004): a below a = 1, 0.88 a^(1/6) above."""
    return _piecewise(a, LUBE_HEIGHT_BREAK, lambda x: x, lambda x: 0.88 * x ** (1.0 / 6.0))


def lajeunesse_runout(a):
    """(r_inf - r0) / r0 of Lajeunesse et al. (2004): 1.35 a below a = 0.74, 2.0 a^0.5 above."""
    return _piecewise(a, LAJEUNESSE_BREAK, lambda x: 1.35 * x, lambda x: 2.0 * np.sqrt(x))


def lajeunesse_height(a):
    """h_inf / r0 of Lajeunesse et al. (2004) as printed in the paper: a below a = 0.74, 0.74 a above."""
    return _piecewise(a, LAJEUNESSE_BREAK, lambda x: x, lambda x: 0.74 * x)


LAWS = {
    "runout_over_r0": {"Lube et al. (2004)": lube_runout, "Lajeunesse et al. (2004)": lajeunesse_runout},
    "h_inf_over_r0": {"Lube et al. (2004)": lube_height, "Lajeunesse et al. (2004)": lajeunesse_height},
}
"""The laws by the summary variable they predict, then by name (for plots and comparisons)."""


def final_values(variable: str, a: float, geometry: str = "cylinder") -> dict:
    """{law name: its value of `variable` at aspect ratio a}, NaN where the law gives no final
    value: Lajeunesse's (2004) height law as printed (0.74 a) above a = 0.74; in a channel, a height
    above the column's initial height a (Lajeunesse's 2005 law as the source prints it, for
    0.7 <= a < 1)."""
    if geometry == "channel":
        return {name: np.nan if variable == "h_inf_over_r0" and float(law(a)) > a else float(law(a))
                for name, law in CHANNEL_LAWS[variable].items()}
    return {name: np.nan if variable == "h_inf_over_r0" and "Lajeunesse" in name and a > LAJEUNESSE_BREAK
            else float(law(a)) for name, law in LAWS[variable].items()}


# ---------------------------------------------------------------------------------------------
# Channel laws: granular columns of length L0 at the end of a rectangular channel, released by
# lifting a gate; a = H0 / L0.
# ---------------------------------------------------------------------------------------------

LUBE_2005_LINEAR_BELOW = 1.8
"""Lube et al. (2005) run-out: the linear regime holds below a = 1.8, the power law above 2.8."""
LUBE_2005_POWER_ABOVE = 2.8
LUBE_2005_HEIGHT_BREAK = 1.15
LAJEUNESSE_2005_RUNOUT_BREAK = 3.0
LAJEUNESSE_2005_HEIGHT_BREAK = 0.7


def lube_2005_runout(a):
    """(L_inf - L0) / L0 of Lube, Huppert, Sparks & Freundt (2005), Phys. Rev. E 72, 041301:
    1.2 a for a < 1.8, 1.9 a^(2/3) for 2.8 <= a < 10; NaN in between, where the two regimes meet
    and no law is given.

    Source: the paper's abstract (read as the bibliography of Kumar's thesis, Cambridge 2015,
    reproduces it) says the collapse "divides in two main flow regimes at a ~ 1.8"; its full text
    was not available. The coefficients and the break points 1.8 and 2.8
    are those that Lagrée, Staron & Popinet (2011), J. Fluid Mech. 686, 378, Eq. (3.1), quote for
    it (lambda_1 = 1.2, lambda_2 = 1.9, exponent 2/3, 1.8 <= a0 <= 2.8), as reproduced in a public
    validation page; Lagrée et al.'s own text was not read either. Other secondary sources
    disagree: Kumar's thesis (Cambridge, 2015, chapter 2) puts a single break at a = 2.3 (1.2 a
    below, 1.9 a^(2/3) above), and a public post-processing script draws 1.6 a and 2.2 a^(2/3)
    blended across 1.8-2.8. The channel width of the experiments is not stated in the sources
    found; the law is applied to every width."""
    return _piecewise(a, LUBE_2005_LINEAR_BELOW, lambda x: 1.2 * x, lambda x: 1.9 * x ** (2.0 / 3.0),
                      above_from=LUBE_2005_POWER_ABOVE)


def lube_2005_height(a):
    """H_inf / L0 of Lube et al. (2005): a for a < 1.15 (the column's top is not lowered), a^(2/5)
    above. Source: Lagrée, Staron & Popinet (2011), Eq. (3.2), as quoted in a public validation
    page (coefficient about 1, exponent about 0.4, for Lube's experiments); the break a = 1.15 is
    the one a public post-processing script of these laws uses. Neither the primary text nor
    Lagrée et al.'s was read. As encoded, the law steps down at a = 1.15 (from 1.15 to 1.057)."""
    return _piecewise(a, LUBE_2005_HEIGHT_BREAK, lambda x: x, lambda x: x ** 0.4)


def lajeunesse_2005_runout(a):
    """(L_inf - L0) / L0 of Lajeunesse, Monnier & Homsy (2005), Phys. Fluids 17, 103302
    (rectangular channel, glass beads): 1.8 a for a < 3, 2.3 a^(2/3) for a >= 3.

    Source: the paper's abstract (read as Kumar's thesis bibliography reproduces it) says the
    run-out and height "exhibit simple power laws whose exponents depend on a and on the flow
    geometry", without numbers. The coefficients and the
    break a0 = 3 are those quoted from Lagrée, Staron & Popinet (2011), Eq. (3.1), in a public
    validation page (lambda_1 = 1.8, lambda_2 = 2.3). As encoded the law steps down at a = 3 (from
    5.4 to 4.78), as a fit of each regime separately would. Kumar (2015) attributes 1.2 a and
    1.9 a^(2/3) with a break at 2.3 to the quasi-two-dimensional experiments instead. Channel width:
    not stated in the sources found."""
    return _piecewise(a, LAJEUNESSE_2005_RUNOUT_BREAK, lambda x: 1.8 * x, lambda x: 2.3 * x ** (2.0 / 3.0))


def lajeunesse_2005_height(a):
    """H_inf / L0 of Lajeunesse et al. (2005) in the rectangular channel: a for a < 0.7, a^(1/3)
    above, as Kumar's thesis (Cambridge, 2015, chapter 2) prints it; the primary text was not
    available. As printed it exceeds a for 0.7 <= a < 1 (a final height above the initial one),
    so a prefactor is probably missing; it is kept as printed, and :func:`final_values` gives no
    value where it exceeds a."""
    return _piecewise(a, LAJEUNESSE_2005_HEIGHT_BREAK, lambda x: x, lambda x: x ** (1.0 / 3.0))


CHANNEL_LAWS = {
    "runout_over_r0": {"Lube et al. (2005)": lube_2005_runout, "Lajeunesse et al. (2005)": lajeunesse_2005_runout},
    "h_inf_over_r0": {"Lube et al. (2005)": lube_2005_height, "Lajeunesse et al. (2005)": lajeunesse_2005_height},
}
"""The channel laws by the summary variable they predict (r0 standing for L0), then by name."""


BALMFORTH_KERSWELL = {
    "wide": {"runout_over_r0": (0.9, 0.1), "h_inf_over_r0": (0.4, None)},
    "narrow": {"runout_over_r0": (0.65, 0.05), "h_inf_over_r0": (0.5, None)},
}
"""Balmforth & Kerswell (2005), J. Fluid Mech. 538, 399, abstract (read on a copy of the paper's
first page): the exponents, with the authors' uncertainty where they give one, of
(l_inf - L)/L ~ a^0.9+-0.1 (wide channels) and a^0.65+-0.05 (narrow slots; also
l_inf/L ~ a^0.55+-0.05), and of H/h_inf ~ a^0.6 (wide) and a^0.5 (narrow), that is
h_inf/L ~ a^0.4 and a^0.5. The authors give no coefficient: "the numerical constant of
proportionality ... shows clear material dependence"; so these are exponents to compare fitted
slopes with, not values. Widths: the abstract says "relatively wide channels" and "much narrower
slots"; Kumar (2015, chapter 2) gives about 200 and 10 grain diameters, not checked against the
primary text. Lacaze, Phillips & Kerswell (2008), Phys. Fluids 20(6), one grain deep (abstract
read in Kumar's thesis bibliography): the run-out follows a power law of a; no exponent or
coefficient was found in the sources available, so no law of theirs is encoded."""


def laws_for(geometry: str) -> dict:
    """The value laws that a study of `geometry` ("cylinder" or "channel") is compared with; the
    first of each variable's laws is the reference (:data:`REFERENCE`)."""
    if geometry not in REFERENCE:
        raise ValueError(f"geometry {geometry!r} is not one of cylinder, channel")
    return CHANNEL_LAWS if geometry == "channel" else LAWS


REFERENCE = {"cylinder": "Lube et al. (2004)", "channel": "Lube et al. (2005)"}
"""The law a study's tables and figures measure errors against, by geometry."""

BREAKPOINTS = {"cylinder": (LAJEUNESSE_BREAK, LUBE_HEIGHT_BREAK, LUBE_RUNOUT_BREAK),
               "channel": (LUBE_2005_LINEAR_BELOW, LUBE_2005_POWER_ABOVE, LUBE_2005_HEIGHT_BREAK,
                           LAJEUNESSE_2005_RUNOUT_BREAK, LAJEUNESSE_2005_HEIGHT_BREAK)}
"""Where each geometry's laws change branch (a figure leaves a gap there rather than draw a jump)."""


def power_law_exponent(a, values) -> float:
    """The exponent b of values ~ c a^b fitted by least squares in log-log (dimensionless), over
    the finite positive pairs; NaN with fewer than two distinct a."""
    a, values = np.asarray(a, dtype=float).ravel(), np.asarray(values, dtype=float).ravel()
    keep = np.isfinite(a) & np.isfinite(values) & (a > 0) & (values > 0)
    if np.unique(a[keep]).size < 2:
        return np.nan
    return float(np.polyfit(np.log(a[keep]), np.log(values[keep]), 1)[0])
