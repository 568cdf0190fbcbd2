# The one-mu_r question on the page's limits (docs/data/calibration_limits.csv), from the repository root:
#   python docs/data/calibration_one_mu_r.py
# Each limit is drawn normal about its estimate, each side's standard deviation its interval's half-width / 1.96
# times Student's t(6)/z, independently of the others (the page holds no per-seed values, so neither the
# packings' sharing nor the size law's exponent range enters); 4,000 draws, seed 0.
import numpy as np
from colsim.study.calibration import GRID_POINTS, worst_errors, widened

data = np.genfromtxt("docs/data/calibration_limits.csv", delimiter=",", names=True, dtype=None, encoding=None,
                     skip_header=4)  # the 4 lines of comment
mu_rs, ratios = np.unique(data["mu_r"]), np.unique(data["aspect_ratio"])
table = np.zeros((3, 2, len(mu_rs), len(ratios)))
for row in data:
    q = 0 if row["measure"] == "height" else 1
    table[:, q, np.searchsorted(mu_rs, row["mu_r"]), np.searchsorted(ratios, row["aspect_ratio"])] = \
        row["limit"], row["low"], row["high"]
limit, low, high = table
grid = np.linspace(mu_rs[0], mu_rs[-1], GRID_POINTS)
widen = 2.447 / 1.960
z = np.random.default_rng(0).standard_normal((4000,) + limit.shape)
draws = limit + np.where(z < 0, limit - low, high - limit) / 1.96 * widen * z
for name, keep in (("every a", ratios > 0), ("a = 1 left out", ratios != 1)):
    worst = worst_errors(limit[..., keep], mu_rs, ratios[keep], "lube", grid)
    boot = worst_errors(draws[..., keep], mu_rs, ratios[keep], "lube", grid)
    minimax = grid[worst.argmin()]
    lo, hi = np.clip(widened(minimax, grid[boot.argmin(-1)], 0.95, 1.0), grid[0], grid[-1])
    print(f"{name}: some mu_r within 10 % in {(boot.min(-1) <= 0.10).mean():.2%} of draws; "
          f"minimax mu_r {minimax:.3f} [{lo:.3f}, {hi:.3f}], worst error {worst.min():.1%}")
