"""The Snakemake study end to end: the tiny configuration (config/tiny.yaml) in a copy of the workflow.

Runs `snakemake -j2 all --configfile config/tiny.yaml` as a user would (a minute or two on 2 cores),
then checks results/tiny/summary.nc, the figures and the report, that adding a seed or a mu_r value
schedules only the new jobs, and that a wrong configuration stops snakemake naming the culprit.
"""
import numpy as np
import pytest
import yaml

from helpers import FIGURES, ROOT, SUMMARY_VARIABLES, TINY, copy_workflow, planned_outputs, snakemake


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    directory = copy_workflow(tmp_path_factory.mktemp("study"))
    result = snakemake(directory, "-j2", "all", "--configfile", "config/tiny.yaml")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-5000:]
    return directory


@pytest.mark.slow
def test_summary_holds_finite_numbers_with_units(tiny_study):
    xr = pytest.importorskip("xarray")
    summary = xr.load_dataset(tiny_study / TINY / "summary.nc")
    assert dict(summary.sizes) == {"aspect_ratio": 2, "mu_r": 2, "seed": 1, "contact_tolerance": 4,
                                   "mass_share": 3}
    assert summary.runout_over_r0_by_tolerance.dims == ("aspect_ratio", "mu_r", "seed", "contact_tolerance")
    np.testing.assert_allclose(summary["aspect_ratio"], [0.5, 1.0])
    np.testing.assert_allclose(summary["mu_r"], [0.0, 0.12])
    for name in SUMMARY_VARIABLES:
        variable = summary[name]
        assert variable.dims == ("aspect_ratio", "mu_r", "seed"), name
        assert np.all(np.isfinite(variable.values)), name
        assert "units" in variable.attrs and "long_name" in variable.attrs, name
    assert np.all(summary["h_inf_over_r0"].values > 0)
    assert np.all(summary["n_particles"].values > 0)
    assert "config" in summary.attrs and "run_configs" in summary.attrs
    table = (tiny_study / TINY / "summary.csv").read_text().splitlines()
    assert len(table) == 1 + 4 and "h_inf_over_r0" in table[0]
    assert "runout_over_r0_by_tolerance_0.5" in table[0] and "mass_front_over_r0_0.95" in table[0]


@pytest.mark.slow
def test_figures_logs_and_benchmarks_exist(tiny_study):
    for name in FIGURES:
        path = tiny_study / TINY / "figures" / f"{name}.png"
        assert path.is_file() and path.stat().st_size > 1000, name
    assert (tiny_study / TINY / "study_config.yaml").is_file()
    logs = list((tiny_study / "results").rglob("*.log"))             # runs' in results/logs, the study's
    benchmarks = list((tiny_study / "results").rglob("*.tsv"))       # in results/tiny/logs
    # pack 1, trim 2, collapse 4, analyse 4, collect, plot, study_config
    assert len(logs) == 14 and len(benchmarks) == 14
    assert not list((tiny_study / "results").rglob("*.checkpoint"))


@pytest.mark.slow
def test_nothing_left_to_do_and_new_values_run_only_new_jobs(tiny_study):
    result = snakemake(tiny_study, "-n", "all", "--configfile", "config/tiny.yaml")
    assert result.returncode == 0
    assert planned_outputs(result) == [], result.stdout

    (tiny_study / "more.yaml").write_text("seeds: [1, 2]\nmu_r: [0, 0.06, 0.12]\n")
    result = snakemake(tiny_study, "-n", "all", "--configfile", "config/tiny.yaml", "more.yaml")
    assert result.returncode == 0, result.stderr[-3000:]
    planned = planned_outputs(result)
    simulated = [p for p in planned if p.startswith("results/r0_")]
    # the tiny study's 40 steps are not the default's, so its runs sit in a folder named for them
    expected_new = {f"results/r0_1/seed_2/a_{a}/mu_r_{m}/steps_40_t_4/collapse.nc"
                    for a in ("0.5", "1") for m in ("0", "0.06", "0.12")}
    expected_new |= {f"results/r0_1/seed_1/a_{a}/mu_r_0.06/steps_40_t_4/collapse.nc" for a in ("0.5", "1")}
    assert {p for p in simulated if p.endswith("collapse.nc")} == expected_new
    assert "results/r0_1/seed_2/packing.nc" in simulated
    assert "results/r0_1/seed_1/packing.nc" not in simulated
    assert not any(p.startswith("results/r0_1/seed_1/") and p.endswith("column.nc") for p in simulated)
    assert f"{TINY}/summary.nc" in planned


@pytest.mark.slow
def test_report_describes_the_study_it_shows(tiny_study):
    """Issue 16, defect 1: the report's text comes from the tiny study's own files, also when the
    configuration that builds the report says otherwise; no Docutils error box."""
    (tiny_study / "other.yaml").write_text("r0: 2\ncollapse: {steps: 77}\nmu_r: [0.3]\n")
    for name, extra in (("report.html", ()), ("other.html", ("other.yaml",))):
        result = snakemake(tiny_study, "--report", name, "--configfile", "config/tiny.yaml", *extra)
        assert result.returncode == 0, result.stderr[-3000:]
        html = (tiny_study / name).read_text(errors="replace")
        assert len(html) > 10000 and "final_height.png" in html
        for text in ("r0 = 1 (diameters 0.25-0.5)", "aspect ratios a: [0.5, 1]", "mu_r: [0, 0.12]",
                     "40 steps to t/sqrt(h0/g) = 4.0", "results/tiny/study_config.yaml"):
            assert text in html, (name, text)
        assert "77 steps" not in html and "r0 = 2" not in html
        assert "System Message" not in html and "Undefined substitution" not in html


@pytest.mark.slow
def test_the_default_study_leaves_the_tiny_study_alone(tiny_study):
    """Each study writes its summary, tables and figures into its own folder."""
    result = snakemake(tiny_study, "-n", "all")
    assert result.returncode == 0, result.stderr[-3000:]
    planned = planned_outputs(result)
    assert "results/summary.nc" in planned and "results/study_config.yaml" in planned
    assert not [p for p in planned if p.startswith(f"{TINY}/")]


def test_a_config_error_across_fields_stops_before_any_job(tmp_path):
    """Issue 16, defect 4: r0 below the largest particle is refused when the configuration is
    checked, with one line naming both, and results/ stays as it was."""
    directory = copy_workflow(tmp_path)
    earlier = directory / TINY / "study_config.yaml"
    earlier.parent.mkdir(parents=True)
    earlier.write_text("r0: 1\n")
    (directory / "r.yaml").write_text("r0: 0.2\n")
    result = snakemake(directory, "-j2", "all", "--configfile", "config/tiny.yaml", "r.yaml", timeout=120)
    assert result.returncode != 0
    lines = [line for line in (result.stdout + result.stderr).splitlines() if line.startswith("config:")]
    assert lines == ["config: r0 0.2 is below diameter_max 0.5: the largest particle does not fit in the cylinder"]
    assert earlier.read_text() == "r0: 1\n"
    assert sorted(p.relative_to(directory).as_posix() for p in (directory / "results").rglob("*")) == [
        "results/tiny", f"{TINY}/study_config.yaml"]


def test_a_failed_run_does_not_rewrite_the_study_config(tmp_path):
    """The study configuration is written only with the summary it describes: a pack that fails
    at run time leaves none."""
    directory = copy_workflow(tmp_path)
    (directory / "fail.yaml").write_text("pack: {max_steps: 1}\n")
    result = snakemake(directory, "-j2", "all", "--configfile", "config/tiny.yaml", "fail.yaml", timeout=300)
    assert result.returncode != 0
    assert not (directory / TINY / "study_config.yaml").exists()
    assert not (directory / TINY / "report_description.rst").exists()


@pytest.mark.parametrize("setting, message", [
    ("bogus_key: 1", "config: unknown key bogus_key; allowed: r0, aspect_ratios,"),
    ("solver: simplex", "config: solver: 'simplex' is not one of"),
    ("r0: -1", "config: r0: -1 is less than or equal to the minimum of 0"),
    ("diameter_min: 0.9", "config: diameter_min 0.9 exceeds diameter_max 0.5"),
    ("aspect_ratios: [0.1, 1]", "config: aspect ratio 0.1 at r0 3 gives h0 = 0.3, below diameter_max 0.5"),
    ("pack_aspect_ratio: 1", "config: pack_aspect_ratio 1 is below the largest aspect ratio 5"),
    ("friction_law: bipotential", "config: friction_law: 'bipotential' is not one of"),
    ("{friction_law: coulomb, friction_law_comparison: true}",
     "config: friction_law_comparison needs friction_law: associated"),
])
def test_a_wrong_configuration_stops_the_run_in_one_line(tmp_path, setting, message):
    """A wrong key or value, or settings that contradict each other, stop snakemake before any job
    with one line naming them (not the schema's dump)."""
    directory = copy_workflow(tmp_path)
    (directory / "bad.yaml").write_text(setting + "\n")
    result = snakemake(directory, "-n", "all", "--configfile", "bad.yaml", timeout=120)
    assert result.returncode != 0
    output = (result.stdout + result.stderr).splitlines()
    lines = [line for line in output if line.startswith("config:")]
    assert len(lines) == 1 and lines[0].startswith(message), result.stderr[-2000:]
    assert len(output) < 10
    assert not (directory / "results").exists()


def test_the_schema_the_cli_and_the_readme_offer_the_same_solvers():
    """colsim.solvers.SOLVERS is the one list: the schema's enum, the CLI's choices and the README's
    table of back-ends hold the same names."""
    yaml = pytest.importorskip("yaml")
    from colsim.cli import build_parser
    from colsim.solvers import SOLVERS

    schema = yaml.safe_load((ROOT / "workflow" / "schemas" / "config.schema.yaml").read_text())
    assert tuple(schema["properties"]["solver"]["enum"]) == SOLVERS
    subcommands = next(a for a in build_parser()._actions if a.dest == "command").choices
    for command in ("pack", "collapse"):
        solver = next(a for a in subcommands[command]._actions if a.dest == "solver")
        assert tuple(solver.choices) == SOLVERS
    table = [line for line in (ROOT / "README.md").read_text().splitlines() if line.startswith("| `")]
    assert {line.split("`")[1] for line in table} >= set(SOLVERS)


def test_a_misspelt_nested_key_stops_the_run(tmp_path):
    directory = copy_workflow(tmp_path)
    (directory / "bad.yaml").write_text("collapse:\n  stepz: 50\n")
    result = snakemake(directory, "-n", "all", "--configfile", "bad.yaml", timeout=120)
    assert result.returncode != 0
    assert "stepz" in result.stdout + result.stderr


def test_the_default_study_plans_every_run(tmp_path):
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "-n", "all", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    planned = planned_outputs(result)
    assert sum(p.endswith("packing.nc") for p in planned) == 2
    assert sum(p.endswith("column.nc") for p in planned) == 2 * 6
    assert sum(p.endswith("collapse.nc") for p in planned) == 2 * 6 * 4
    assert sum(p.endswith("analysis.nc") for p in planned) == 2 * 6 * 4


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(path.name for path in (ROOT / "config").glob("*.yaml")))
def test_every_named_configuration_plans(tmp_path, name):
    """Each study config/*.yaml that the README offers as one command passes the schema and the
    cross-field checks, and plans at least one collapse (a dry run: nothing is simulated)."""
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "-n", "all", "--configfile", f"config/{name}", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    assert any(path.endswith("collapse.nc") for path in planned_outputs(result))


def test_the_convergence_study_plans_its_runs(tmp_path):
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "-n", "all", "--configfile", "config/convergence.yaml", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    planned = set(planned_outputs(result))
    run = "results/r0_2/seed_1/a_{a}/mu_r_0.12"
    for a in ("2", "5"):   # 1,000 steps stopped at t = 4: not the default study's run to rest
        for variant in ("steps_250_t_4", "steps_500_t_4", "steps_1000_t_4", "steps_2000_t_4", "steps_2000_t_8"):
            assert f"{run.format(a=a)}/{variant}/collapse.nc" in planned
        assert f"{run.format(a=a)}/collapse.nc" not in planned
    assert "results/r0_3/seed_1/a_2/mu_r_0.12/steps_1000_t_4/collapse.nc" in planned
    for r0, seeds in (("2", "123"), ("3", "123"), ("4", "1")):   # small columns run on to t = 8
        for a in ("0.5", "1"):
            for seed in seeds:
                assert f"results/r0_{r0}/seed_{seed}/a_{a}/mu_r_0.12/steps_2000_t_8/collapse.nc" in planned
    assert "results/r0_4/seed_2/packing.nc" not in planned
    assert "results/r0_4/seed_1/a_2/mu_r_0.12/collapse.nc" not in planned
    assert {f"results/r0_2/seed_{s}/a_2/mu_r_0.12/steps_1000_t_4/collapse.nc" for s in range(1, 6)} <= planned
    assert "results/r0_2/seed_3/a_5/mu_r_0.12/steps_1000_t_4/collapse.nc" in planned
    assert {"results/convergence/summary.nc", "results/convergence/lube_table.md",
            "results/convergence/convergence.nc", "results/convergence/figures/convergence.png"} <= planned


def test_a_run_to_rest_and_a_run_stopped_at_its_end_time_keep_separate_folders(tmp_path):
    """The default study (1,000 steps, on to rest) and a study of the same columns stopped at
    t/sqrt(h0/g) = 4 (max_duration: null) plan different runs: neither overwrites the other."""
    directory = copy_workflow(tmp_path)
    (directory / "fixed.yaml").write_text("collapse: {max_duration: null}\nstudy: fixed\n")
    to_rest = snakemake(directory, "-n", "-p", "all", timeout=120)
    fixed = snakemake(directory, "-n", "-p", "all", "--configfile", "fixed.yaml", timeout=120)
    assert to_rest.returncode == 0 and fixed.returncode == 0, to_rest.stderr[-3000:] + fixed.stderr[-3000:]
    rest_runs = {p for p in planned_outputs(to_rest) if p.endswith("collapse.nc")}
    fixed_runs = {p for p in planned_outputs(fixed) if p.endswith("collapse.nc")}
    assert len(rest_runs) == len(fixed_runs) == 48 and not rest_runs & fixed_runs
    assert all(p.endswith("/steps_1000_t_4/collapse.nc") for p in fixed_runs)
    assert "--max-duration 12 " in to_rest.stdout and "--max-duration" not in fixed.stdout


def test_the_friction_law_study_plans_both_laws(tmp_path):
    """config/friction-law.yaml: each of its 9 runs under both laws (the Coulomb ones in coulomb/,
    with --friction-law coulomb), and the comparison; a study under coulomb alone keeps its runs
    there too, so it never overwrites an associated run."""
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "-n", "-p", "all", "--configfile", "config/friction-law.yaml", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    planned = set(planned_outputs(result))
    run = "results/r0_2/seed_{s}/a_{a}/mu_r_0.12"
    for s in "123":
        for a in ("0.5", "2", "5"):
            assert f"{run.format(s=s, a=a)}/collapse.nc" in planned
            assert f"{run.format(s=s, a=a)}/coulomb/analysis.nc" in planned
    assert {"results/friction-law/friction_law.md", "results/friction-law/figures/friction_law.png"} <= planned
    commands = [line for line in result.stdout.splitlines() if "colsim collapse" in line]
    assert sum("--friction-law coulomb --friction-tolerance 1e-05" in c and "/coulomb/collapse.nc" in c
               for c in commands) == 9
    assert not any("--friction-tolerance" in c for c in commands if "/coulomb/" not in c)
    assert sum("--friction-law associated" in c and "/coulomb/" not in c for c in commands) == 9
    (directory / "coulomb.yaml").write_text("friction_law: coulomb\n")
    alone = snakemake(directory, "-n", "all", "--configfile", "config/tiny.yaml", "coulomb.yaml", timeout=120)
    assert alone.returncode == 0, alone.stderr[-3000:]
    collapses = [p for p in planned_outputs(alone) if p.endswith("collapse.nc")]
    assert collapses and all(p.endswith("/coulomb/collapse.nc") for p in collapses)


def plan_with_and_without(tmp_path, setting: str):
    """The tiny study's dry runs (-n -p) with the YAML `setting` added and without it."""
    directory = copy_workflow(tmp_path)
    (directory / "setting.yaml").write_text(setting)
    on = snakemake(directory, "-n", "-p", "all", "--configfile", "config/tiny.yaml", "setting.yaml", timeout=120)
    off = snakemake(directory, "-n", "-p", "all", "--configfile", "config/tiny.yaml", timeout=120)
    assert on.returncode == 0 and off.returncode == 0, on.stderr[-3000:] + off.stderr[-3000:]
    return on, off


def test_run_to_rest_reaches_the_collapse_command(tmp_path):
    """collapse.max_duration set: every study collapse gets the rest options; unset (the paper):
    none does, and the command is the fixed-length one."""
    on, off = plan_with_and_without(tmp_path, "collapse: {max_duration: 8, rest_tolerance: 0.2}\n")
    commands = [line for line in on.stdout.splitlines() if "colsim collapse" in line]
    assert len(commands) == 4
    assert all("--max-duration 8 --rest-window 1.0 --rest-tolerance 0.2 --rest-energy 0.01" in c for c in commands)
    assert "--max-duration" not in off.stdout and "colsim collapse" in off.stdout


def test_the_overlap_tolerance_reaches_the_collapse_only_when_set(tmp_path):
    """solver_overlap_tolerance: 0 reaches every `colsim collapse` (not the packing); unset (null,
    colsim's default) the command is as before the key existed, so no finished run is redone."""
    on, off = plan_with_and_without(tmp_path, "solver_overlap_tolerance: 0\n")
    commands = [line for line in on.stdout.splitlines() if "colsim collapse" in line]
    assert len(commands) == 4 and all("--solver auto --solver-overlap-tolerance 0 " in c for c in commands)
    assert "overlap-tolerance" not in off.stdout and "--solver auto " in off.stdout
    packs = [line for line in on.stdout.splitlines() if "colsim pack" in line]
    assert packs and not any("overlap" in line for line in packs)


def test_mu_r_reaches_the_collapse_at_full_precision(tmp_path):
    """pi/24 names its folder mu_r_0.1309 but reaches `colsim collapse` with all its digits."""
    directory = copy_workflow(tmp_path)
    (directory / "hexagon.yaml").write_text("mu_r: [0.1308996938995747]\n")
    result = snakemake(directory, "-n", "-p", "all", "--configfile", "config/tiny.yaml", "hexagon.yaml", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    commands = [line for line in result.stdout.splitlines() if "colsim collapse" in line]
    assert len(commands) == 2 and all("--mu-r 0.1308996938995747 " in c for c in commands), commands
    assert all("mu_r_0.1309/steps_40_t_4/collapse.nc" in c for c in commands)


TINY_CONVERGENCE = """
convergence:
  mu_r: 0.12
  time_step: {aspect_ratios: [0.5], steps: [40, 80]}
  end_time: {aspect_ratios: [0.5], duration: 6.0}
  column_size: [{aspect_ratio: 0.5, r0: [1, 1.25]}, {aspect_ratio: 1, r0: [1.25], duration: 6.0}]
  seeds: {aspect_ratio: 0.5, seeds: [1, 2]}
"""


@pytest.mark.slow
def test_a_tiny_convergence_study_runs_end_to_end(tiny_study):
    """The tiny study plus a convergence block: only the new runs are made, and the table, its
    Markdown and the figure hold finite numbers for all four sub-studies."""
    xr = pytest.importorskip("xarray")
    (tiny_study / "tiny_convergence.yaml").write_text(TINY_CONVERGENCE)
    arguments = ("all", "--configfile", "config/tiny.yaml", "tiny_convergence.yaml")
    result = snakemake(tiny_study, "-j2", *arguments)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-5000:]
    table = xr.load_dataset(tiny_study / TINY / "convergence.nc")
    assert sorted(set(table.study.values)) == ["column_size", "end_time", "seeds", "time_step"]
    assert table.sizes["run"] == 2 + 1 + 3 + 2
    assert np.all(np.isfinite(table.h_inf_over_r0.values)) and np.all(np.isfinite(table.runout_over_r0.values))
    end = table.where(table.study == "end_time", drop=True)
    assert np.isfinite(end.runout_over_r0_at_default_end.values).all()
    text = (tiny_study / TINY / "convergence.md").read_text()
    assert "### Time step" in text and "### Seeds" in text
    assert (tiny_study / TINY / "figures" / "convergence.png").stat().st_size > 10000
    lube = (tiny_study / TINY / "lube_table.md").read_text()
    assert "| Lube |" in lube and "| 0.5 | " in lube and "| 1 | " in lube


def test_every_simulating_rule_has_its_slurm_resources(tmp_path):
    """A rule made by `use rule` (collapse_variant, collapse_coulomb, ...) does not get its parent's
    resources from the SLURM profile: each must be named there, with at least its parent's."""
    directory = copy_workflow(tmp_path)
    listed = snakemake(directory, "--list-rules", timeout=120)
    assert listed.returncode == 0, listed.stderr[-3000:]
    rules = {line.split()[0] for line in listed.stdout.splitlines() if line.strip()}
    profile = yaml.safe_load((ROOT / "workflow" / "profiles" / "slurm" / "config.yaml").read_text())
    resources = profile["set-resources"]
    for parent in ("collapse", "analyse"):
        children = {rule for rule in rules if rule.startswith(parent)}
        assert {parent, f"{parent}_variant", f"{parent}_coulomb"} <= children
        for rule in children:
            assert rule in resources, f"{rule} has no resources in workflow/profiles/slurm"
            for key in ("runtime", "mem_mb"):
                assert resources[rule][key] >= resources[parent][key], (rule, key)


def test_a_packing_filled_with_friction_has_its_own_tree(tmp_path):
    """pack.mu > 0 packs and runs below results/pack_mu_{mu}/ (logs and benchmarks too), with
    --mu reaching colsim pack: the default packings' runs are never overwritten."""
    directory = copy_workflow(tmp_path)
    (directory / "loose.yaml").write_text("pack: {mu: 0.2}\n")
    result = snakemake(directory, "-n", "-p", "all", "--configfile", "config/tiny.yaml", "loose.yaml", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    runs = [p for p in planned_outputs(result) if p.endswith(("packing.nc", "column.nc", "collapse.nc", "analysis.nc"))]
    assert len(runs) == 1 + 2 + 4 + 4
    assert all(p.startswith("results/pack_mu_0.2/r0_1/seed_1/") for p in runs), runs
    assert "--mu 0.2 " in result.stdout and "results/pack_mu_0.2/logs/r0_1/seed_1/pack.log" in result.stdout


def test_the_friction_tolerance_has_one_default():
    """config.yaml, the schema and colsim (FrictionLaw, so the CLI) agree on the fixed point's tolerance."""
    from colsim.state import FrictionLaw
    schema = yaml.safe_load((ROOT / "workflow" / "schemas" / "config.schema.yaml").read_text())
    config = yaml.safe_load((ROOT / "config.yaml").read_text())
    assert schema["properties"]["friction_tolerance"]["default"] == config["friction_tolerance"] == FrictionLaw().tolerance
