# The column-size limits at p = 1 from the page's means (docs/data/column-size-limits.csv), from the
# repository root:
#   python docs/data/column_size_p1.py
# The least-squares fit X = X_inf + k d/r0 over every run equals the fit over each size's mean
# weighted by its seeds (three up to r0 = 4, two above), so the means give the p = 1 limits (to
# their rounding, 0.001); d/r0's scale moves k only. The intervals need the runs, which are not kept.
import csv

import numpy as np

from colsim.study.experimental_laws import lube_height, lube_runout
from colsim.study.size_limit import fit_limit

SIZES = (2, 3, 4, 5, 6)
with open("docs/data/column-size-limits.csv", encoding="utf-8") as file:
    rows = list(csv.DictReader(line for line in file if not line.startswith("#")))
print("a, measure, limit printed, limit at p = 1, vs Lube")
for row in rows:
    sizes = [r0 for r0 in SIZES if row[f"r0_{r0}"]]
    seeds = [3 if r0 <= 4 else 2 for r0 in sizes]
    x = np.repeat([1.0 / r0 for r0 in sizes], seeds)
    y = np.repeat([float(row[f"r0_{r0}"]) for r0 in sizes], seeds)
    a, limit = float(row["aspect_ratio"]), fit_limit(x, y).x_inf
    lube = float((lube_height if row["variable"] == "h_inf_over_r0" else lube_runout)(a))
    print(f"{a:g}, {row['variable']}, {row['limit']}, {limit:.3f}, {100 * (limit / lube - 1):+.0f} %")
