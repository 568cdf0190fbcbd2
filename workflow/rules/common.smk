# Configuration check and the helpers that name the study's files (no physics here).
from snakemake.utils import validate

validate(config, "../schemas/config.schema.yaml")

if config["diameter_min"] > config["diameter_max"]:
    raise ValueError(
        f"config: diameter_min {config['diameter_min']} exceeds diameter_max {config['diameter_max']}"
    )


def fmt(value):
    """A number as it appears in paths and on the colsim command line: 1 -> '1', 0.06 -> '0.06'."""
    return f"{float(value):g}"


R0 = fmt(config["r0"])
ASPECT_RATIOS = [fmt(a) for a in config["aspect_ratios"]]
MU_R = [fmt(m) for m in config["mu_r"]]
SEEDS = [str(s) for s in config["seeds"]]
PACK_ASPECT_RATIO = config["pack_aspect_ratio"] or max(config["aspect_ratios"])
if PACK_ASPECT_RATIO < max(config["aspect_ratios"]):
    raise ValueError(
        f"config: pack_aspect_ratio {PACK_ASPECT_RATIO} is below the largest aspect ratio "
        f"{max(config['aspect_ratios'])}"
    )

# the figures that `colsim plot` writes (colsim.plots.FIGURES), with their report captions
FIGURES = {
    "final_height": "Final height",
    "runout": "Run-out",
    "mu_r_effect": "Effect of rolling resistance",
    "deposit_profiles": "Deposit profiles",
    "side_views": "Side views",
    "front_position": "Front position",
}

RUN = "results/r0_{r0}/seed_{seed}/a_{a}/mu_r_{mu_r}"

wildcard_constraints:
    r0=r"[0-9][0-9.e+-]*",
    a=r"[0-9][0-9.e+-]*",
    mu_r=r"[0-9][0-9.e+-]*",
    seed=r"[0-9]+",


def runs(name, mu_r=None, seeds=None):
    """Paths of one file `name` of every run of the study (optionally one mu_r, some seeds)."""
    return expand(
        f"{RUN}/{name}",
        r0=R0,
        seed=seeds or SEEDS,
        a=ASPECT_RATIOS,
        mu_r=MU_R if mu_r is None else [mu_r],
    )


def side_view_mu_r():
    """The swept mu_r nearest to figures.side_view_mu_r."""
    target = config["figures"]["side_view_mu_r"]
    return min(MU_R, key=lambda m: abs(float(m) - target))


def pack_height(wildcards):
    """Height the packing of radius r0 must exceed: pack_aspect_ratio (or the largest a) times r0."""
    return fmt(PACK_ASPECT_RATIO * float(wildcards.r0))


def collapse_priority(wildcards):
    """Scheduling priority of a collapse: 10 a, so that the costliest columns run first."""
    return int(round(10 * float(wildcards.a)))


def output_directory(wildcards, output):
    """The directory of a rule's first output (for commands that take --output-dir)."""
    return os.path.dirname(output[0])


def figures():
    return expand("results/figures/{figure}.png", figure=FIGURES)


# cheap jobs that a cluster run keeps on the submitting node
localrules:
    all,
    study_config,
