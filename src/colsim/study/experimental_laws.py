"""Experimental scaling laws of the final deposit (SPEC section 5; the paper's Eqs. 1-4).

Every function takes the aspect ratio a = h0 / r0 (scalar or array, dimensionless) and returns a
float or an array of the same shape: the run-out (r_inf - r0) / r0 or the final height h_inf / r0.
The laws were measured for 0 <= a < 10; outside that range (and for NaN input) they return NaN.

- Lube et al. (2004): run-out 1.24 a (a < 1.7), 1.6 a^0.5 (1.7 <= a < 10);
  height a (a < 1), 0.88 a^(1/6) (1 <= a < 10).
- Lajeunesse et al. (2004): run-out 1.35 a (a < 0.74), 2.0 a^0.5 (0.74 <= a < 10);
  height a (a < 0.74), 0.74 a (a >= 0.74).

The Lajeunesse height law is kept exactly as the paper prints it (its Eq. 4). As printed it jumps at
a = 0.74 (from 0.74 to 0.548); it is drawn as printed and the jump is left visible.
"""
from __future__ import annotations

import numpy as np

LUBE_RUNOUT_BREAK = 1.7
LUBE_HEIGHT_BREAK = 1.0
LAJEUNESSE_BREAK = 0.74
LARGEST_ASPECT_RATIO = 10.0

__all__ = ["lube_runout", "lube_height", "lajeunesse_runout", "lajeunesse_height", "LAWS"]


def _piecewise(a, brk, below, above):
    """below(a) for 0 <= a < brk, above(a) for brk <= a < 10, NaN elsewhere; scalar in, float out."""
    values = np.asarray(a, dtype=float)
    with np.errstate(invalid="ignore"):
        safe = np.where(values >= 0, values, 0.0)
        result = np.where(values < brk, below(safe), above(safe))
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


def final_values(variable: str, a: float) -> dict:
    """{law name: its value of `variable` at aspect ratio a}, NaN where the law gives no final
    value: Lajeunesse's height law as printed (0.74 a) above a = 0.74."""
    return {name: np.nan if variable == "h_inf_over_r0" and "Lajeunesse" in name and a > LAJEUNESSE_BREAK
            else float(law(a)) for name, law in LAWS[variable].items()}
