"""Rolling-resistance coefficient of a regular polygon by the paper's reasoning (Eqs. 7-10).

A regular N-gon of side l resting on a side under a load p must be tipped over a vertex to roll.
At the start the load's line of action is l/2 from that vertex, so a moment tau_max = p l / 2 is
needed. The paper takes the resisting moment to fall linearly to zero over the first half of a
roll cycle and to stay zero over the second half, so its average is tau_ave = tau_max / 4 = p l / 8
(the hexagon: Eq. 8). Mapping the polygon to a disc of the same perimeter, N l = 2 pi r (Eq. 7), and
equating tau_ave to the disc's resisting moment mu_r r p (Eq. 9) gives

    mu_r = l / (8 r) = pi / (4 N)          (hexagon: pi / 24 = 0.131, Eq. 10).

method="exact" replaces the linear fall by the true lever arm R_c sin(pi/N - theta) of a polygon
pivoting about a vertex (R_c = l / (2 sin(pi/N)) its circumradius), averaged over one cycle of
2 pi/N: tau_ave = p R_c (1 - cos(pi/N)) N / (2 pi), so mu_r = R_c (1 - cos(pi/N)) N / (2 pi r);
the hexagon gives 0.134, and both tend to 0 like 1/N as the polygon tends to the disc.
"""
from __future__ import annotations

import numpy as np


def polygon_rolling_coefficient(sides: int, method: str = "paper") -> float:
    """mu_r of a regular polygon with `sides` sides (>= 3); method 'paper' (Eq. 10) or 'exact'."""
    if int(sides) != sides or sides < 3:
        raise ValueError(f"a regular polygon needs an integer number of sides >= 3, got {sides}")
    n = int(sides)
    if method == "paper":
        return np.pi / (4.0 * n)
    if method == "exact":
        side = 2.0 * np.pi / n                       # l for a disc of radius r = 1
        circumradius = side / (2.0 * np.sin(np.pi / n))
        return circumradius * (1.0 - np.cos(np.pi / n)) * n / (2.0 * np.pi)
    raise ValueError(f"method must be 'paper' or 'exact', got {method!r}")
