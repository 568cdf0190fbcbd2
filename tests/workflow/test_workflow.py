"""The Snakemake study end to end: the tiny configuration (config/tiny.yaml) in a copy of the workflow.

Runs `snakemake -j2 all --configfile config/tiny.yaml` as a user would (a minute or two on 2 cores),
then checks results/tiny/summary.nc, the figures and the report, that adding a seed or a mu_r value
schedules only the new jobs, and that a wrong configuration stops snakemake naming the culprit.
"""
import json
import os
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr
import yaml

from helpers import (FIGURES, ROOT, RUN_PATH, SUMMARY_VARIABLES, TINY, cf_check_failures, copy_workflow,
                     planned_collapses, planned_outputs, planned_settings, snakemake)

from colsim import io
from colsim.study.workflow.plan import fmt


def is_analysis(path: str) -> bool:
    """Whether `path` is a run's analysis (analysis_KEY.nc, KEY that of its analysis settings)."""
    return re.search(r"/run_[0-9a-f]{10}/analysis_[0-9a-f]{10}\.nc$", path) is not None


def tiny_analyses(directory, study=TINY) -> list:
    """The analyses a study's summary collected (its `colsim collect` inputs), in order."""
    summary = xr.load_dataset(directory / study / "summary.nc")
    return [directory / path for path in json.loads(summary.attrs["config"])["inputs"]]


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    directory = copy_workflow(tmp_path_factory.mktemp("study"))
    result = snakemake(directory, "-j2", "all", "--configfile", "config/tiny.yaml")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-5000:]
    return directory


@pytest.mark.slow
def test_summary_holds_finite_numbers_with_units(tiny_study):
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
    # issue 29: at 100 steps `auto` gives every warm-started step to APGD (the first of each run,
    # started from the packing's forces, too); Clarabel takes only a step APGD could not finish
    backends = json.loads(summary.attrs["solver_backends"])
    assert backends.get("apgd", 0) >= 0.9 * 4 * 100, backends
    assert summary.attrs["rolling_lever"] == "paper"
    table = (tiny_study / TINY / "summary.csv").read_text().splitlines()
    assert len(table) == 1 + 4 and "h_inf_over_r0" in table[0]
    assert "runout_over_r0_by_tolerance_0.5" in table[0] and "mass_front_over_r0_0.95" in table[0]


@pytest.mark.slow
def test_the_study_files_pass_the_cf_checker(tiny_study):
    """Bound: no error or warning of the IOOS checker's CF-1.8 suite (tests/io/test_netcdf.py) in the
    tiny study's packing, column, trajectory, analysis and summary; at_rest is a flag everywhere."""
    run = sorted(tiny_study.glob("results/r0_1/seed_1/pack_*/a_*/mu_r_0.12/run_*"))[0]
    paths = [run.parents[2] / "packing.nc", run.parents[1] / "column.nc", run / "collapse.nc",
             *tiny_analyses(tiny_study)[:1], tiny_study / TINY / "summary.nc"]
    for path in paths:
        assert cf_check_failures(path) == [], path
    for path in paths[2:]:
        at_rest = xr.load_dataset(path)["at_rest"]
        assert at_rest.dtype == np.int8 and set(np.unique(at_rest.values)) <= set(at_rest.attrs["flag_values"])


@pytest.mark.slow
def test_paraview_series_read_back_and_leave_the_collapses_alone(tiny_study):
    """`snakemake paraview` exports the side-view runs (first seed, mu_r nearest 0.12, both a) from
    their collapse.nc without running any collapse again; meshio (an independent VTK reader) reads
    every frame back with the netCDF's positions and radii, and the .pvd's times are t/sqrt(h0/g)."""
    import meshio

    collapses = sorted(tiny_study.glob("results/r0_1/seed_1/pack_*/a_*/mu_r_0.12/run_*/collapse.nc"))
    assert len(collapses) == 2
    before = {path: path.stat().st_mtime_ns for path in tiny_study.glob("results/**/collapse.nc")}
    result = snakemake(tiny_study, "-j2", "paraview", "--configfile", "config/tiny.yaml", timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "colsim collapse" not in result.stdout + result.stderr
    assert {path: path.stat().st_mtime_ns for path in before} == before
    for collapse in collapses:
        trajectory = io.open_dataset(collapse, io.TRAJECTORY_KIND)
        pvd = collapse.parent / "vtk" / "collapse.pvd"
        entries = re.findall(r'timestep="([^"]+)"[^>]*file="([^"]+)"', pvd.read_text())
        assert len(entries) == trajectory.sizes["time"]
        np.testing.assert_allclose([float(t) for t, _ in entries], trajectory["scaled_time"].values, rtol=1e-8)
        for k, (_, frame) in enumerate(entries):
            mesh = meshio.read(pvd.parent / frame)
            np.testing.assert_array_equal(mesh.points, trajectory["position"].values[k])
            np.testing.assert_array_equal(mesh.point_data["radius"].ravel(), trajectory["radius"].values)


@pytest.mark.slow
def test_figures_logs_and_benchmarks_exist(tiny_study):
    for name in FIGURES:
        path = tiny_study / TINY / "figures" / f"{name}.png"
        assert path.is_file() and path.stat().st_size > 1000, name
    assert (tiny_study / TINY / "study_config.yaml").is_file()
    # runs' in results/logs, the study's in results/tiny/logs (the paraview test's exports aside)
    logs = [p for p in (tiny_study / "results").rglob("*.log") if p.name != "export_vtk.log"]
    benchmarks = [p for p in (tiny_study / "results").rglob("*.tsv") if p.name != "export_vtk.tsv"]
    # pack 1, trim 2, collapse 4, analyse 4, collect, plot, study_config; and the settings files'
    # (a packing's, 4 runs', the analyses', the study's), which have no benchmark
    assert len(logs) == 14 + 7 and len(benchmarks) == 14
    assert not list((tiny_study / "results").rglob("*.checkpoint"))
    collapse_logs = list((tiny_study / "results" / "logs").rglob("collapse.log"))
    assert len(collapse_logs) == 4 and all(" by apgd" in log.read_text() for log in collapse_logs)
    settings = list((tiny_study / "results").rglob("settings.yaml"))   # 1 packing and 4 runs
    assert len(settings) == 5 and any('"rolling_lever": "paper"' in s.read_text() for s in settings)


@pytest.mark.slow
def test_study_cost_reads_the_studys_own_benchmark_files(tiny_study, tmp_path):
    """`python -m benchmarks study_cost` on the study's results: one row a packing and one a
    collapse, each with the CPU, wall and memory of its Snakemake benchmark file (none resumed),
    the spheres of its file, and APGD's iterations a step."""
    env = {**os.environ, "COLSIM_BENCHMARK_RESULTS": str(tmp_path), "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", "benchmarks", "study_cost", str(tiny_study / "results"),
                           "--aspect-ratio", "0.5", "1"], cwd=ROOT, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    (record,) = tmp_path.glob("study_cost-*.json")
    jobs, sizes = json.loads(record.read_text())["tables"]
    packs = [row for row in jobs["data"] if "a" not in row]
    runs = [row for row in jobs["data"] if "a" in row]
    assert len(packs) == 1 and len(runs) == 4
    for row in packs + runs:
        assert row["cpu"] > 0 and row["wall"] > 0 and row["rss"] > 0 and not row["resumed"]
        assert row["cpu_file"] > 0 and row["cpu_all"] == row["cpu_file"]   # the file's CPU, all segments
    collapses = sorted((tiny_study / "results").rglob("collapse.nc"))
    assert sorted(row["spheres"] for row in runs) == sorted(
        int(xr.load_dataset(path).attrs["n_particles"]) for path in collapses)
    assert all(row["iterations"] > 0 for row in runs)
    assert [row["r0"] for row in sizes["data"]] == [1.0, 1.0]   # one size, at a = 0.5 and at a = 1


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
    new = {RUN_PATH.match(p).group("seed", "a", "mu_r") for p in simulated if p.endswith("collapse.nc")}
    expected = {("2", a, m) for a in ("0.5", "1") for m in ("0", "0.06", "0.12")}
    expected |= {("1", a, "0.06") for a in ("0.5", "1")}
    assert new == expected
    packings = [p for p in simulated if p.endswith("packing.nc")]
    assert len(packings) == 1 and packings[0].startswith("results/r0_1/seed_2/pack_")
    assert not any(p.startswith("results/r0_1/seed_1/") and p.endswith("column.nc") for p in simulated)
    assert f"{TINY}/summary.nc" in planned


@pytest.mark.slow
@pytest.mark.parametrize("setting", ["contact_tolerance: 0.05", "check_tolerances: [0.2, 0.5, 1.0]",
                                     "mass_shares: [0.8, 0.95]"])
def test_changed_analysis_settings_rerun_the_analyses_and_nothing_upstream(tiny_study, setting):
    """Issue 48.1: every analysis has its settings' key file as an input, so a changed analysis
    setting plans the 4 analyses and what follows them (the summary, figures, study files), and no
    packing, column or collapse."""
    (tiny_study / "analysis.yaml").write_text(f"analysis: {{{setting}}}\n")
    result = snakemake(tiny_study, "-n", "all", "--configfile", "config/tiny.yaml", "analysis.yaml")
    assert result.returncode == 0, result.stderr[-3000:]
    planned = planned_outputs(result)
    assert sum(map(is_analysis, planned)) == 4, planned
    assert f"{TINY}/summary.nc" in planned and f"{TINY}/study_config.yaml" in planned
    assert not any(p.endswith(("collapse.nc", "packing.nc", "column.nc")) for p in planned), planned


@pytest.mark.slow
def test_a_rewritten_rule_does_not_redo_its_results(tiny_study):
    """profiles/default: a rule whose command or parameters were edited (here the pack rule gains
    a parameter and an option, as when pack.layer_height came) redoes nothing: a result's settings
    are its folder's key, so only a missing or outdated file is made again."""
    rules = tiny_study / "workflow" / "rules" / "simulate.smk"
    original = rules.read_text()
    edited = original.replace('        max_spheres=config["pack"]["max_spheres"],\n',
                              '        max_spheres=config["pack"]["max_spheres"],\n        edited=1,\n', 1)
    edited = edited.replace("--max-spheres {params.max_spheres} --threads", "--max-spheres {params.max_spheres} --verbose --threads", 1)
    assert edited.count("edited=1") == 1 and "--verbose --threads" in edited
    rules.write_text(edited)
    try:
        result = snakemake(tiny_study, "-n", "all", "--configfile", "config/tiny.yaml")
    finally:
        rules.write_text(original)
    assert result.returncode == 0, result.stderr[-3000:]
    assert planned_outputs(result) == [], result.stdout


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
        for text in ("r0 = 1, a: [0.5, 1]", "mu_r: [0, 0.12]", "seeds: [1]",
                     "100 steps to t/sqrt(h0/g) = 4.0", "results/tiny/study_config.yaml",
                     "steps by back-end", "apgd: ", "lever paper", "A smoke test, not a result",
                     "mu_r = 0.12, mean over seeds, against Lube et al. (2004)", "(r_inf - r0)/r0"):
            assert text in html, (name, text)
        assert "77 steps" not in html and "r0 = 2" not in html
        assert "System Message" not in html and "Undefined substitution" not in html


#: a page holding the report in a frame of a laptop's screen, which puts in its title where the
#: caveat's first words lie in that frame once the report has drawn itself (Chromium, headless)
CAVEAT_PROBE = """<!DOCTYPE html><html><head><title>waiting</title><style>body{{margin:0}}
iframe{{border:0;width:{width}px;height:{height}px;display:block}}</style></head><body>
<iframe id="report" src="{report}"></iframe><script>
function look() {{
  const page = document.getElementById("report").contentDocument;
  const caveat = page && [...page.querySelectorAll("strong")].find(e => e.textContent.includes("{words}"));
  if (!caveat) {{ document.title = "caveat not found"; return; }}
  const box = caveat.getBoundingClientRect();
  document.title = "caveat from " + Math.round(box.top) + " to " + Math.round(box.bottom);
}}
window.addEventListener("load", () => setTimeout(look, 3000));
</script></body></html>"""


@pytest.mark.slow
@pytest.mark.skipif(not (shutil.which("chromium") or shutil.which("chromium-browser")),
                    reason="no Chromium (Debian: apt install chromium)")
def test_the_report_shows_its_caveat_on_a_laptop_screen(tiny_study, tmp_path):
    """Issue 79.2: the tiny study's report opened at 1280x800 in a real browser (headless Chromium)
    shows "A smoke test, not a result" inside the screen (before: Snakemake centres its landing page,
    which was taller than the screen, and the caveat lay 51 px above its top)."""
    result = snakemake(tiny_study, "--report", "caveat.html", "--configfile", "config/tiny.yaml")
    assert result.returncode == 0, result.stderr[-3000:]
    width, height = 1280, 800
    probe = tmp_path / "probe.html"
    probe.write_text(CAVEAT_PROBE.format(width=width, height=height, report=(tiny_study / "caveat.html").as_uri(),
                                         words="A smoke test, not a result"))
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    done = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
                           f"--window-size={width},{height}", "--virtual-time-bud" "get=10000", "--dump-dom",
                           probe.as_uri()], capture_output=True, text=True, timeout=180)
    title = re.search(r"<title>(.*?)</title>", done.stdout)
    assert title and title.group(1).startswith("caveat from "), (title, done.stderr[-2000:])
    top, bottom = map(int, title.group(1).split()[2::2])
    assert 0 <= top and bottom <= height, title.group(1)


@pytest.mark.slow
def test_a_plotting_setting_rewrites_the_report_s_pages_too(tiny_study):
    """Issue 79.5: figures.side_view_mu_r changes the landing table (at that mu_r) and the
    configuration the report shows, so both are planned again with the plot (before: the plot only)
    and nothing else; the study as it was is still up to date."""
    (tiny_study / "side_view.yaml").write_text("figures: {side_view_mu_r: 0}\n")
    result = snakemake(tiny_study, "-n", "all", "--configfile", "config/tiny.yaml", "side_view.yaml")
    assert result.returncode == 0, result.stderr[-3000:]
    planned = planned_outputs(result)
    for path in (f"{TINY}/study_config.yaml", f"{TINY}/report_description.rst", f"{TINY}/figures/side_views.png"):
        assert path in planned, (path, planned)
    assert not [p for p in planned if p.endswith((".nc", "lube_table.md"))], planned
    assert planned_outputs(snakemake(tiny_study, "-n", "all", "--configfile", "config/tiny.yaml")) == []


@pytest.mark.slow
def test_two_studies_that_analyse_alike_runs_differently_keep_both(tiny_study):
    """Issue 79.4: a study that differs from the tiny one only in its analysis settings shares the
    tiny study's collapses and writes its own analyses beside them (before: it overwrote the tiny
    study's analysis.nc, which each study then planned again). Run one after the other, then again:
    nothing is planned, and each summary holds its own analyses' numbers, made with its settings."""
    (tiny_study / "tiny_b.yaml").write_text("study: tiny_b\nanalysis: {contact_tolerance: 0.05}\n")
    studies = {TINY: ("config/tiny.yaml",), "results/tiny_b": ("config/tiny.yaml", "tiny_b.yaml")}
    result = snakemake(tiny_study, "-j2", "all", "--configfile", *studies["results/tiny_b"])
    assert result.returncode == 0, result.stderr[-3000:]
    assert "colsim collapse" not in result.stdout + result.stderr and "colsim pack" not in result.stdout + result.stderr
    for configs in studies.values():
        planned = snakemake(tiny_study, "-n", "all", "--configfile", *configs)
        assert planned.returncode == 0 and planned_outputs(planned) == [], planned.stdout[-2000:]
    collected = {study: tiny_analyses(tiny_study, study) for study in studies}
    assert not set(collected[TINY]) & set(collected["results/tiny_b"])
    for study, tolerance in ((TINY, 0.01), ("results/tiny_b", 0.05)):
        summary = xr.load_dataset(tiny_study / study / "summary.nc")
        for path in collected[study]:
            analysis = xr.load_dataset(path)
            assert json.loads(analysis.attrs["config"])["contact_tolerance"] == tolerance, path
            here = summary.sel(aspect_ratio=float(analysis.aspect_ratio), mu_r=float(analysis.mu_r),
                               seed=int(analysis.seed))
            assert float(here.h_inf_over_r0) == float(analysis.h_inf_over_r0)
            assert float(here.runout_over_r0) == float(analysis.runout_over_r0)


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
    # issue 28's probes: NaN and inf pass a schema's minimum and maximum; a name with a final newline
    # passes a `$` pattern; a size out of reach; an alias bomb and a configuration that refers to itself
    ("mu_r: [.nan]", "config: mu_r.0: must be a finite number"),
    ("collapse: {max_duration: .inf}", "config: collapse.max_duration: must be a finite number"),
    ("figures: {side_view_mu_r: .nan}", "config: figures.side_view_mu_r: must be a finite number"),
    ('study: "evil\\n"', "config: study: 'evil\\n' may hold only letters"),
    ("r0: 1000", "config: a packing of r0 1000 for a = 5 would hold about"),
    ("a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
     "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
     "e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: [*e, *e, *e, *e, *e, *e, *e, *e, *e, *e]",
     "config: more than 100,000 keys and values once YAML's aliases are expanded"),
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


def test_a_configuration_too_deep_for_snakemakes_reader_is_reported_by_it_and_writes_nothing(tmp_path):
    """Issue 80.7: a mapping 5,000 levels deep fails in Snakemake's YAML reader, before the Snakefile
    runs, so colsim cannot name it. docs/study-config.md says so: Snakemake's traceback ends in the
    reader's RecursionError, and nothing is planned or written."""
    directory = copy_workflow(tmp_path)
    depth = 5000
    (directory / "deep.yaml").write_text("study: deep\nr0: " + "{a: " * depth + "1" + "}" * depth + "\n")
    result = snakemake(directory, "-n", "all", "--configfile", "deep.yaml", timeout=120)
    assert result.returncode != 0
    last_lines = [stream.strip().splitlines()[-1] for stream in (result.stdout, result.stderr) if stream.strip()]
    assert any(line.startswith("RecursionError") for line in last_lines), last_lines
    assert not (directory / "results").exists()
    assert "RecursionError" in (ROOT / "docs" / "study-config.md").read_text()


def test_the_schema_the_cli_and_the_docs_offer_the_same_solvers():
    """colsim.solvers.SOLVERS is the one list: the schema's enum, the CLI's choices and the table of
    back-ends in docs/solvers.md hold the same names."""
    from colsim.cli import build_parser
    from colsim.solvers import SOLVERS

    schema = yaml.safe_load((ROOT / "workflow" / "schemas" / "config.schema.yaml").read_text())
    assert tuple(schema["properties"]["solver"]["enum"]) == SOLVERS
    subcommands = next(a for a in build_parser()._actions if a.dest == "command").choices
    for command in ("pack", "collapse"):
        solver = next(a for a in subcommands[command]._actions if a.dest == "solver")
        assert tuple(solver.choices) == SOLVERS
    table = [line for line in (ROOT / "docs" / "solvers.md").read_text().splitlines() if line.startswith("| `")]
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
    assert sum(map(is_analysis, planned)) == 2 * 6 * 4


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(path.name for path in (ROOT / "config").glob("*.yaml")))
def test_every_named_configuration_plans(tmp_path, name):
    """Each study config/*.yaml that the docs offer as one command passes the schema and the
    cross-field checks, and plans at least one collapse (a dry run: nothing is simulated)."""
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "-n", "all", "--configfile", f"config/{name}", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    assert any(path.endswith("collapse.nc") for path in planned_outputs(result))


def steps_and_end(collapse: dict) -> tuple[str, str, bool]:
    """(steps, end time, whether it goes on to rest) of a planned collapse, from its settings."""
    settings = collapse["settings"]
    return str(settings["steps"]), fmt(settings["duration"]), settings["rest"] is not None


def test_the_convergence_study_plans_its_runs(tmp_path):
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "-n", "-p", "all", "--configfile", "config/convergence.yaml", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    runs = {(c["r0"], c["seed"], c["a"], c["mu_r"]) + steps_and_end(c) for c in planned_collapses(result)}
    assert all(run[3] == "0.12" for run in runs)
    for a in ("2", "5"):   # 1,000 steps stopped at t = 4: not the default study's run to rest
        for steps, end in (("250", "4"), ("500", "4"), ("1000", "4"), ("2000", "4"), ("2000", "8")):
            assert ("2", "1", a, "0.12", steps, end, False) in runs
        assert ("2", "1", a, "0.12", "1000", "4", True) not in runs
    assert ("3", "1", "2", "0.12", "1000", "4", False) in runs
    for r0, seeds in (("2", "123"), ("3", "123"), ("4", "1")):   # small columns run on to t = 8
        for a in ("0.5", "1"):
            for seed in seeds:
                assert (r0, seed, a, "0.12", "2000", "8", False) in runs
    assert not any(run[:2] == ("4", "2") for run in runs)
    assert not any(run[:3] == ("4", "1", "2") for run in runs)
    assert {("2", str(s), "2", "0.12", "1000", "4", False) for s in range(1, 6)} <= runs
    assert ("2", "3", "5", "0.12", "1000", "4", False) in runs
    planned = set(planned_outputs(result))
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
    rest_runs = {c["path"] for c in planned_collapses(to_rest)}
    fixed_runs = {c["path"] for c in planned_collapses(fixed)}
    assert len(rest_runs) == len(fixed_runs) == 48 and not rest_runs & fixed_runs
    assert all(c["settings"]["rest"]["max_duration"] == 12 for c in planned_collapses(to_rest))
    assert all(c["settings"]["rest"] is None for c in planned_collapses(fixed))


def test_the_friction_law_study_plans_both_laws(tmp_path):
    """config/friction-law.yaml: each of its 9 columns under both laws, in folders of their own
    (the law is part of a run's key), with --friction-law coulomb and its tolerance for the Coulomb
    ones, and the comparison; a study under coulomb alone plans the Coulomb runs only."""
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "-n", "-p", "all", "--configfile", "config/friction-law.yaml", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    collapses = planned_collapses(result)
    coulomb = [c for c in collapses if c["settings"]["friction_law"] == "coulomb"]
    associated = [c for c in collapses if c["settings"]["friction_law"] == "associated"]
    assert len(coulomb) == len(associated) == 9 and len(collapses) == 18
    columns = {(c["seed"], c["a"]) for c in coulomb}
    assert columns == {(c["seed"], c["a"]) for c in associated} == {(s, a) for s in "123" for a in ("0.5", "2", "5")}
    assert not {c["path"] for c in coulomb} & {c["path"] for c in associated}
    assert all(c["settings"]["friction_tolerance"] == 1e-05 for c in coulomb)
    assert all(c["settings"]["friction_tolerance"] is None for c in associated)
    planned = set(planned_outputs(result))
    assert {"results/friction-law/friction_law.md", "results/friction-law/figures/friction_law.png"} <= planned
    # a Coulomb run's cluster time limit comes from its settings: 24 h against 2 h
    blocks = result.stdout.split("\nrule ")
    limits = [line for block in blocks if block.startswith("collapse:")
              for line in block.splitlines() if "runtime=" in line and "mem_mb=4000" in line]
    assert sum("runtime=1440" in line for line in limits) == 9 and sum("runtime=120" in line for line in limits) == 9
    (directory / "coulomb.yaml").write_text("friction_law: coulomb\n")
    alone = snakemake(directory, "-n", "-p", "all", "--configfile", "config/tiny.yaml", "coulomb.yaml", timeout=120)
    assert alone.returncode == 0, alone.stderr[-3000:]
    runs = planned_collapses(alone)
    assert runs and all(c["settings"]["friction_law"] == "coulomb" for c in runs)


def plan_with_and_without(tmp_path, setting: str):
    """The tiny study's dry runs (-n -p) with the YAML `setting` added and without it."""
    directory = copy_workflow(tmp_path)
    (directory / "setting.yaml").write_text(setting)
    on = snakemake(directory, "-n", "-p", "all", "--configfile", "config/tiny.yaml", "setting.yaml", timeout=120)
    off = snakemake(directory, "-n", "-p", "all", "--configfile", "config/tiny.yaml", timeout=120)
    assert on.returncode == 0 and off.returncode == 0, on.stderr[-3000:] + off.stderr[-3000:]
    return on, off


def test_run_to_rest_reaches_the_collapse_settings(tmp_path):
    """collapse.max_duration set: every study collapse's settings hold the rest options; unset (the
    paper): none do, and the run is the fixed-length one. Each collapse reads its settings file."""
    on, off = plan_with_and_without(tmp_path, "collapse: {max_duration: 8, rest_tolerance: 0.2}\n")
    runs = planned_collapses(on)
    assert len(runs) == 4 and all(f"--settings {c['path'].rsplit('/', 1)[0]}/settings.yaml" in c["command"] for c in runs)
    assert all(c["settings"]["rest"] == {"max_duration": 8.0, "rest_window": 1.0, "rest_tolerance": 0.2,
                                         "rest_energy": 0.01} for c in runs)
    assert [c["settings"]["rest"] for c in planned_collapses(off)] == [None] * 4


def test_the_overlap_tolerance_reaches_the_collapse_only_when_set(tmp_path):
    """solver_overlap_tolerance: 0 reaches every `colsim collapse` (not the packing); unset (null,
    colsim's default) the command is as before the key existed, so no finished run is redone."""
    on, off = plan_with_and_without(tmp_path, "solver_overlap_tolerance: 0\n")
    runs = planned_collapses(on)
    assert len(runs) == 4 and all(c["settings"]["solver_overlap_tolerance"] == 0 for c in runs)
    assert all(c["settings"]["solver_overlap_tolerance"] is None for c in planned_collapses(off))
    packs = [settings for path, settings in planned_settings(on).items() if "/run_" not in path and "pack_" in path]
    assert packs and not any("overlap" in json.dumps(settings) for settings in packs)


def test_mu_r_reaches_the_collapse_at_full_precision(tmp_path):
    """pi/24 names its folder and reaches `colsim collapse` with all its digits; two values closer
    than %g shows (0.1000001, 0.1000002) are two runs in two folders."""
    directory = copy_workflow(tmp_path)
    (directory / "hexagon.yaml").write_text("mu_r: [0.1308996938995747]\n")
    result = snakemake(directory, "-n", "-p", "all", "--configfile", "config/tiny.yaml", "hexagon.yaml", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    runs = planned_collapses(result)
    assert len(runs) == 2 and all(c["settings"]["mu_r"] == 0.1308996938995747 for c in runs), runs
    assert all("/mu_r_0.1308996938995747/run_" in c["path"] for c in runs)
    (directory / "close.yaml").write_text("mu_r: [0.1000001, 0.1000002]\naspect_ratios: [1]\n")
    result = snakemake(directory, "-n", "-p", "all", "--configfile", "config/tiny.yaml", "close.yaml", timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    assert sorted(c["mu_r"] for c in planned_collapses(result)) == ["0.1000001", "0.1000002"]


TINY_CONVERGENCE = """
convergence:
  mu_r: 0.12
  time_step: {aspect_ratios: [0.5], steps: [100, 200]}
  end_time: {aspect_ratios: [0.5], duration: 6.0}
  column_size: [{aspect_ratio: 0.5, r0: [1, 1.25]}, {aspect_ratio: 1, r0: [1.25], duration: 6.0}]
  seeds: {aspect_ratio: 0.5, seeds: [1, 2]}
"""


@pytest.mark.slow
def test_a_tiny_convergence_study_runs_end_to_end(tiny_study):
    """The tiny study plus a convergence block: only the new runs are made, and the table, its
    Markdown and the figure hold finite numbers for all four sub-studies."""
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


def test_the_slurm_profile_names_only_rules_that_exist(tmp_path):
    """Every rule the SLURM profile sizes exists (one collapse rule serves every run; its time limit
    comes from the run's settings, test_the_friction_law_study_plans_both_laws), and the rules that
    simulate are sized there or in the rule (pack and collapse in theirs, by the column's size)."""
    directory = copy_workflow(tmp_path)
    listed = snakemake(directory, "--list-rules", timeout=120)
    assert listed.returncode == 0, listed.stderr[-3000:]
    rules = {line.split()[0] for line in listed.stdout.splitlines() if line.strip()}
    profile = yaml.safe_load((ROOT / "workflow" / "profiles" / "slurm" / "config.yaml").read_text())
    resources = profile["set-resources"]
    assert set(resources) <= rules
    assert "analyse" in resources and {"pack", "collapse"} <= rules
    assert not {"pack", "collapse"} & set(resources)   # the profile would override the rules' sizing


def plan_two_studies(tmp_path, other: str):
    """The simulation outputs of dry runs of the tiny study and of the tiny study with the YAML `other`."""
    directory = copy_workflow(tmp_path)
    (directory / "other.yaml").write_text(other)
    first = snakemake(directory, "-n", "all", "--configfile", "config/tiny.yaml", timeout=120)
    second = snakemake(directory, "-n", "all", "--configfile", "config/tiny.yaml", "other.yaml", timeout=120)
    assert first.returncode == 0 and second.returncode == 0, first.stderr[-3000:] + second.stderr[-3000:]
    return ({p for p in planned_outputs(first) if p.startswith("results/r0_")},
            {p for p in planned_outputs(second) if p.startswith("results/r0_")})


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
@pytest.mark.parametrize("other, shares_packings", [
    ("study: sb\nmu: 0.3\n", True),
    ("study: sb\nroot_seed: 7\n", False),
    ("study: sb\npack: {mu: 0.2}\n", False),
    ("study: sb\nrolling_lever: effective\n", True),
    ("study: sb\ncollapse: {frame_every: 2}\n", True),
    ("study: sb\naspect_ratios: [0.5]\n", False),   # a shorter packing: another computation
])
def test_two_studies_share_a_file_only_when_it_is_the_same_computation(tmp_path, other, shares_packings):
    """Issue 28: a study that differs from the tiny one in one setting plans no collapse of the tiny
    study's; it shares the packings and columns only when their settings are the same."""
    first, second = plan_two_studies(tmp_path, other)
    collapses = [{p for p in plan if p.endswith("collapse.nc") or is_analysis(p)} for plan in (first, second)]
    assert collapses[0] and collapses[1] and not collapses[0] & collapses[1]
    packings = [{p for p in plan if p.endswith(("packing.nc", "column.nc"))} for plan in (first, second)]
    assert bool(packings[0] & packings[1]) == shares_packings


def test_a_folder_whose_settings_the_study_does_not_have_is_an_error(tmp_path):
    """A target whose key names settings this configuration does not hold is refused, naming the
    folder, instead of being made with this configuration's settings."""
    directory = copy_workflow(tmp_path)
    for target, message in (
            ("pack_0123456789/a_1/mu_r_0.12/run_0123456789/collapse.nc",   # its run's settings are looked up first
             "no run of this study has the folder mu_r_0.12/run_0123456789"),
            ("pack_0123456789/packing.nc", "no packing of this study has the folder r0_1/seed_1/pack_0123456789")):
        result = snakemake(directory, "-n", f"results/r0_1/seed_1/{target}", "--configfile", "config/tiny.yaml",
                           timeout=120)
        assert result.returncode != 0 and message in result.stdout + result.stderr, result.stderr[-2000:]


def test_the_friction_tolerance_has_one_default():
    """config.yaml, the schema and colsim (FrictionLaw, so the CLI) agree on the fixed point's tolerance."""
    from colsim.engine.state import FrictionLaw
    schema = yaml.safe_load((ROOT / "workflow" / "schemas" / "config.schema.yaml").read_text())
    config = yaml.safe_load((ROOT / "config.yaml").read_text())
    assert schema["properties"]["friction_tolerance"]["default"] == config["friction_tolerance"] == FrictionLaw().tolerance


def test_the_lint_asks_only_for_a_conda_environment(tmp_path):
    """`snakemake --lint`: every rule has its log, no long run directive; what is left is the request
    for a conda environment or container a rule, declined in the Snakefile (the pip lock is the
    environment)."""
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "--lint", timeout=120)
    lints = set(re.findall(r"^    \* (.+?):?$", result.stdout + result.stderr, flags=re.M))
    assert lints == {"Specify a conda environment or container for each rule."}, lints
    assert "conda environment" in (directory / "Snakefile").read_text()
    assert "`snakemake --lint` exits 1" in (ROOT / "docs" / "study-config.md").read_text()   # where users look



@pytest.mark.slow
def test_the_convergence_table_passes_the_cf_checker(tiny_study, tmp_path):
    """Issue 48.7: `colsim convergence` on the tiny study's analyses (as a seeds study): its table
    passes the CF-1.8 checker at strict level, as the stages' files and the calibration's do."""
    from helpers import main_in

    analyses = [str(p) for p in tiny_analyses(tiny_study)]   # other tests of this module add runs beside them
    assert len(analyses) == 4
    assert main_in(tmp_path, ["convergence", "--seeds", *analyses, "--default-end", "4",
                              "--output", "convergence.nc"]) == 0
    assert cf_check_failures(tmp_path / "convergence.nc") == []


def test_nolock_is_refused_with_its_reason_before_any_job(tmp_path):
    """Issue 80.8: with --nolock, the second of two studies sharing runs failed on "Incomplete files"
    (the first one's running jobs); the study now refuses --nolock before any job, saying why. A dry
    run, which runs nothing, keeps it."""
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "-j1", "--nolock", "--configfile", "config/tiny.yaml", "--until", "run_settings",
                       timeout=300)
    assert result.returncode != 0 and "--nolock: studies here share their runs" in result.stdout + result.stderr
    assert not (directory / "results").exists()
    assert snakemake(directory, "-n", "--nolock", "all", "--configfile", "config/tiny.yaml", timeout=300).returncode == 0


@pytest.mark.slow
def test_the_tiny_channel_study_runs_end_to_end(tmp_path):
    """config/tiny-channel.yaml from a copy of the workflow: a channel's pours, trims, collapses and
    analyses at two box lengths, its summary against the channel laws of 2005, the run-outs by box
    length, and a report page that names the channel; every file says it holds a channel."""
    directory = copy_workflow(tmp_path)
    result = snakemake(directory, "-j2", "all", "--configfile", "config/tiny-channel.yaml")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-5000:]
    study = directory / "results" / "tiny-channel"
    summary = xr.load_dataset(study / "summary.nc")
    assert summary.attrs["geometry"] == "channel" and summary.attrs["channel_length"] == 1.0
    assert np.isfinite(summary.runout_over_r0.values).all() and np.isfinite(summary.h_inf_over_r0.values).all()
    convergence = xr.load_dataset(study / "length_convergence.nc")
    assert list(convergence.channel_length.values) == [1.0, 1.5]
    assert np.isfinite(convergence.relative_spread.values).all()
    assert "L0 = 1.5" in (study / "length_convergence.md").read_text()
    assert "channel laws" in (study / "report_description.rst").read_text()
    for path in (directory / "results").glob("r0_*/seed_1/pack_*/a_1/mu_r_0.12/run_*/collapse.nc"):
        assert xr.open_dataset(path).attrs["geometry"] == "channel"
    # the study's cost names the channel, so that it is not averaged with a cylinder of r0 = L0
    env = {**os.environ, "COLSIM_BENCHMARK_RESULTS": str(tmp_path / "records"), "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", "benchmarks", "study_cost", str(directory / "results"),
                           "--aspect-ratio", "1"], cwd=ROOT, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    (record,) = (tmp_path / "records").glob("study_cost-*.json")
    jobs, sizes = json.loads(record.read_text())["tables"]
    assert {row["column"] for row in jobs["data"] + sizes["data"]} == {"channel W = 1"}
    assert sorted(row["r0"] for row in sizes["data"]) == [1.0, 1.5]
