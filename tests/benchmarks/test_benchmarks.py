"""The benchmarks' entry point (`python -m benchmarks`) and their records (benchmarks/record.py).

No timing is checked: only that the entry point runs, and that a record holds what it should.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from colsim import io

REPOSITORY = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPOSITORY / "benchmarks"))

import record   # noqa: E402

NAMES = ("apgd_iteration", "cold_step", "collapse", "crossover", "cuda_operator", "device_copies", "gpu", "host_work",
         "packings", "ptx", "scatter", "solvers", "step", "stopping", "study_cost", "threads", "tolerance", "trajectory",
         "kernel_trace", "checkpoints")
FIELDS = ("benchmark", "arguments", "date", "wall_s", "complete", "machine", "versions", "git", "notes", "tables")


def benchmarks(*args, env: dict | None = None) -> subprocess.CompletedProcess:
    """`python -m benchmarks ARGS` from the repository, with this checkout's colsim first."""
    path = os.pathsep.join([str(REPOSITORY / "src"), str(REPOSITORY), os.environ.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-m", "benchmarks", *args], cwd=REPOSITORY, capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": path, **(env or {})}, timeout=600)


def check_fields(content: dict) -> None:
    assert set(FIELDS) <= set(content)
    assert {"cpu", "cores", "memory_gib"} <= set(content["machine"]) and content["machine"]["cores"] >= 1
    assert {"python", "numpy", "scipy", "numba", "clarabel"} <= set(content["versions"])
    assert content["versions"]["numpy"]
    assert {"commit", "dirty"} <= set(content["git"])


def test_list_names_every_benchmark_with_a_description():
    done = benchmarks("list")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert sorted(line.split()[0] for line in lines) == sorted(NAMES)
    assert all(len(line.split(maxsplit=1)) == 2 for line in lines), "a benchmark without a description"


def test_every_benchmark_imports():
    """Each benchmark module loads with this checkout's colsim (a name it imports that colsim no longer
    has fails here, not hours into `all`)."""
    code = "import importlib, sys; [importlib.import_module(name) for name in sys.argv[1:]]"
    path = os.pathsep.join([str(REPOSITORY / "src"), str(REPOSITORY / "benchmarks"), os.environ.get("PYTHONPATH", "")])
    done = subprocess.run([sys.executable, "-c", code, *NAMES], cwd=REPOSITORY, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": path}, timeout=600)
    assert done.returncode == 0, done.stderr


def test_unknown_benchmark_is_an_error():
    done = benchmarks("no_such_benchmark")
    assert done.returncode != 0 and "list" in done.stderr


def test_one_benchmark_writes_its_record(tmp_path):
    """The smallest benchmark (a settled packing of 30 spheres, in a cache under tmp_path) writes one
    record with the machine, the versions, the commit, the arguments and the printed table's rows."""
    results = tmp_path / "results"
    done = benchmarks("--results", str(results), "packings", "30", "--seed", "3",
                      env={record.CACHE_ENV: str(tmp_path / "cache")})
    assert done.returncode == 0, done.stderr
    files = list(results.glob("packings-*.json"))
    assert len(files) == 1 and not list(results.glob(".*"))   # no temporary file left
    content = json.loads(files[0].read_text())
    check_fields(content)
    assert content["benchmark"] == "packings" and content["arguments"] == ["30", "--seed", "3"]
    assert content["complete"] is True
    assert content["git"]["commit"] is None or len(content["git"]["commit"]) == 40
    (table,) = content["tables"]
    assert table["columns"][:2] == ["target", "spheres"]
    assert table["rows"] == [dict(zip(table["columns"], row)) for row in
                             ([c.strip() for c in line.strip("|").split("|")] for line in done.stdout.splitlines()
                              if line.startswith("| 30 "))]
    assert table["data"][0]["spheres"] == 30
    assert (tmp_path / "cache" / "settled_v2_30_seed3.npz").exists()


# record.py on its own


def test_table_prints_and_keeps_its_rows(capsys):
    rec = record.Record("demo", ["--x", 1])
    table = rec.table(["a", "b"], title="t")
    table.row(1, "2.50", data={"a": 1, "b": 2.5})
    table.row("x", "y")
    assert capsys.readouterr().out.splitlines() == ["| a | b |", "|---|---|", "| 1 | 2.50 |", "| x | y |"]
    assert rec.as_dict()["tables"] == [{"title": "t", "columns": ["a", "b"],
                                        "rows": [{"a": "1", "b": "2.50"}, {"a": "x", "b": "y"}],
                                        "data": [{"a": 1, "b": 2.5}]}]
    assert rec.arguments == ["--x", "1"]
    with pytest.raises(ValueError):
        table.row(1)


def test_write_is_atomic_and_names_are_unique(tmp_path):
    rec = record.Record("demo")
    rec.table(["a"], echo=False).row(1)
    first, second = rec.write(tmp_path), rec.write(tmp_path)
    assert first != second and first.name.startswith("demo-") and first.name.endswith("Z.json")
    assert second.name == first.name.replace(".json", "-2.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([first.name, second.name])
    content = json.loads(first.read_text())
    check_fields(content)
    assert content["tables"][0]["rows"] == [{"a": "1"}]


def test_write_json_leaves_the_old_file_when_it_fails(tmp_path):
    path = record.write_json(tmp_path / "r.json", {"a": 1})
    with pytest.raises(TypeError):
        record.write_json(path, {1j: 2})   # a key JSON cannot hold: fails half-way through
    assert json.loads(path.read_text()) == {"a": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_run_writes_a_record_only_with_tables(tmp_path, monkeypatch):
    monkeypatch.setenv(record.RESULTS_ENV, str(tmp_path))

    def quiet(argv):
        return "done"

    def measures(argv):
        record.note("setup", {"n": 3})
        record.table(["n"]).row(3)

    assert record.run("quiet", quiet, []) == "done"
    assert not list(tmp_path.iterdir())   # a child process (--one) or a help text: no file
    record.run("measures", measures, ["--n", "3"])
    (path,) = tmp_path.glob("measures-*.json")
    content = json.loads(path.read_text())
    assert content["arguments"] == ["--n", "3"] and content["notes"] == {"setup": {"n": 3}}
    assert record.current() is None


def test_a_failed_run_keeps_its_rows_marked_incomplete(tmp_path):
    def fails(argv):
        record.table(["n"], echo=False).row(1)
        raise RuntimeError("solver diverged")

    with pytest.raises(RuntimeError):
        record.run("fails", fails, [], folder=tmp_path)
    content = json.loads(next(tmp_path.glob("fails-*.json")).read_text())
    assert content["complete"] is False and "solver diverged" in content["notes"]["error"]
    assert content["tables"][0]["rows"] == [{"n": "1"}]


def test_machine_versions_and_commit():
    machine = record.machine()
    assert machine["cpu"] and machine["cores"] >= 1 and machine["usable_cores"] >= 1
    versions = record.versions()
    assert versions["python"].count(".") == 2 and versions["numpy"]
    state = record.git_state(REPOSITORY)
    assert state["commit"] is None or (len(state["commit"]) == 40 and isinstance(state["dirty"], bool))
    assert record.git_state(Path("/"))["commit"] is None   # not a repository: no commit, no error


# study_cost.py: the figures it reads and the growth it reports


def test_study_cost_reads_a_jobs_benchmark_file_and_marks_resumed_jobs(tmp_path):
    """A job's figures come from its Snakemake benchmark file (the last line); a job whose wall is
    under 0.9 of its file's wall over all segments was resumed from a checkpoint."""
    import study_cost

    run = tmp_path / "r0_4" / "seed_1" / "pack_x" / "packing.nc"
    tsv = tmp_path / "benchmarks" / "r0_4" / "seed_1" / "pack_x" / "pack.tsv"
    tsv.parent.mkdir(parents=True)
    tsv.write_text("s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
                   "3873.60\t1:04:33\t676.99\t919.42\t563.98\t610.69\t8.32\t37.74\t33.91\t1314.41\n")
    bench = study_cost.benchmark_of(tmp_path, run, "pack.tsv")
    assert bench == {"wall": 3873.60, "cpu": 1314.41, "rss": 676.99}
    assert study_cost.benchmark_of(tmp_path, run, "collapse.tsv") is None
    assert study_cost.with_benchmark({"wall_all": 9870.0}, bench)["resumed"] is True
    assert study_cost.with_benchmark({"wall_all": 3900.0}, bench)["resumed"] is False
    assert study_cost.with_benchmark({"wall_all": 3900.0, "resumed_from": 300}, bench)["resumed"] is True
    # the CPU over all segments: the file's where it has one; a resumed job's last segment is not the whole
    assert study_cost.with_benchmark({"wall_all": 9870.0, "cpu_file": 5202.7}, bench)["cpu_all"] == 5202.7
    assert study_cost.with_benchmark({"wall_all": 9870.0, "cpu_file": float("nan")}, bench)["cpu_all"] is None
    assert study_cost.with_benchmark({"wall_all": 3900.0}, bench)["cpu_all"] == 1314.41


def test_study_cost_growth_is_the_log_log_slope_between_sizes():
    """cost = N^1.25 exactly gives k = 1.25 between every pair of sizes; the first size has none."""
    import study_cost

    sizes = [(n, 3.0 * n ** 1.25) for n in (2_474.0, 8_447.0, 20_388.0)]
    k = study_cost.growth(sizes)
    assert k[0] is None
    assert k[1:] == pytest.approx([1.25, 1.25], rel=1e-12)


# scatter.py: the same-answer check's runs


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_scatter_collapses_the_column_and_its_perturbed_copies(tmp_path):
    """`benchmarks scatter` on two stacked spheres: the settings' own run, one at another APGD tolerance
    and one from moved positions, each collapsed and analysed in a child process, recorded one JSON
    line each; a second call finds them all in the record and runs nothing."""
    from helpers import tiny_state_files

    tiny_state_files(tmp_path)
    settings = tmp_path / "settings.yaml"
    settings.write_text('{"steps": 5, "duration": 0.2, "max_duration": null, "mu_r": 0.12, "frame_every": 5}\n')
    record_file = tmp_path / "records" / "scatter.jsonl"   # in a folder not there yet
    arguments = ["--results", str(tmp_path / "results"), "scatter", str(tmp_path / "column.nc"), "--settings",
                 str(settings), "--tolerances", "1e-6", "--draws", "1", "--record", str(record_file)]
    done = benchmarks(*arguments)
    assert done.returncode == 0, done.stderr
    runs = [json.loads(line) for line in record_file.read_text().splitlines()]
    assert sorted(r["kind"] for r in runs) == ["draw", "settings", "tolerance"]
    for r in runs:   # two spheres at rest on the floor stay there: the stack's top at h0 = r0 = 1, its edge
        assert r["steps"] == 5 and r["device"] == "cpu"   # at 0.25 (run-out -0.75), within the overlap
        assert abs(r["h_inf_over_r0"] - 1.0) < 5e-5      # tolerance APGD stops at (1e-4 d, d = 0.5)
        assert abs(r["runout_over_r0"] + 0.75) < 5e-5
    assert "| cpu | 3 |" in done.stdout
    again = benchmarks(*arguments)
    assert again.returncode == 0 and len(record_file.read_text().splitlines()) == 3


def test_a_perturbed_column_moves_each_position_by_at_most_epsilon_diameters(tmp_path):
    import scatter
    from helpers import tiny_state_files

    tiny_state_files(tmp_path)
    moved = scatter.perturbed(tmp_path / "column.nc", 3, 1e-3, tmp_path)
    before, _ = io.read_state(tmp_path / "column.nc")
    after, dataset = io.read_state(moved)
    change = np.abs(after.position - before.position)
    assert 0 < change.max() <= 1e-3 * 0.5 and "default_rng(3)" in dataset.attrs["scatter_perturbation"]
    assert scatter.draws_of("1-3,7") == [1, 2, 3, 7]
    assert scatter.recorded_device("cuda", "float32") == "cuda-float32"
    assert scatter.recorded_device("cpu") == "cpu"


def test_the_means_test_tells_a_shifted_scatter_from_the_same_one():
    """scatter.compared on draws of one law and of that law shifted by three standard deviations:
    the difference of the means is the shift to within its standard error, the p of both tests is
    large for the same law and small for the shifted one, and the difference's interval holds 0 for
    the same law only (fixed draws, so the same every run)."""
    import scatter

    rng = np.random.default_rng(46)
    cpu, same = rng.normal(1.7, 0.07, 45), rng.normal(1.7, 0.07, 9)
    shifted = same + 0.21
    alike, apart = scatter.compared(cpu, same), scatter.compared(cpu, shifted)
    assert abs(apart["difference"] - alike["difference"] - 0.21) < 1e-12
    assert abs(alike["difference"]) < 3 * 0.07 * np.sqrt(1 / 45 + 1 / 9)
    assert alike["p_welch"] > 0.05 and alike["p_mann_whitney"] > 0.05 and alike["t"] * alike["difference"] >= 0
    assert apart["p_welch"] < 1e-3 and apart["p_mann_whitney"] < 1e-3 and apart["t"] > 0
    # the 95 % interval holds the difference, and holds 0 exactly where Welch's p is above 0.05
    for c in (alike, apart):
        assert c["low"] < c["difference"] < c["high"]
    assert alike["low"] < 0 < alike["high"] and apart["low"] > 0


def test_every_cuda_kernel_a_collapse_launches_compiles_for_a_card(tmp_path):
    """`benchmarks ptx`, where numba-cuda and libNVVM are installed (no card needed; else skipped):
    every kernel a GPU collapse launches on the simulator compiles to PTX for sm_90 with the argument
    types it was launched with, and some of them hold FMAs."""
    path = os.pathsep.join([str(REPOSITORY / "benchmarks"), str(REPOSITORY / "src"), os.environ.get("PYTHONPATH", "")])
    probe = subprocess.run([sys.executable, "-c", "import ptx; print(ptx.compiler_missing())"], capture_output=True,
                           text=True, env={**os.environ, "NUMBA_ENABLE_CUDASIM": "0", "PYTHONPATH": path})
    assert probe.returncode == 0, probe.stderr
    if probe.stdout.strip():
        pytest.skip(probe.stdout.strip())
    done = benchmarks("--results", str(tmp_path), "ptx")
    assert done.returncode == 0, done.stderr[-3000:]
    (written,) = tmp_path.glob("ptx-*.json")
    rows = json.loads(written.read_text())["tables"][0]["data"]
    modules = {row["module"] for row in rows}
    assert {"colsim.engine.cuda_contacts", "colsim.engine.cuda_operator", "colsim.engine.cuda_state",
            "colsim.engine.cuda_warm_start", "colsim.engine.cuda_apgd"} <= modules
    assert all(row["error"] == "" for row in rows), [r for r in rows if r["error"]]
    assert sum(row["fma"] for row in rows) > 0


ADD_ONE_PTX = """.version 99.9
.target sm_90
.address_size 64

.visible .entry add_one(.param .u64 p)
{
	.reg .b64 	%rd<3>;
	.reg .f64 	%fd<3>;
	ld.param.u64 	%rd1, [p];
	cvta.to.global.u64 	%rd2, %rd1;
	ld.global.f64 	%fd1, [%rd2];
	add.f64 	%fd2, %fd1, 0d3FF0000000000000;
	st.global.f64 	[%rd2], %fd2;
	ret;
}
"""


def test_an_sm_holds_the_threads_its_registers_allow():
    """benchmarks/ptx.py's occupancy by registers on compute capability 9.0 (64 K registers and 64 warps
    an SM, a warp's registers in units of 256), blocks of 256 threads: APGD's projection kernel's 112
    registers a thread allow two blocks (18 warps' worth), 80 three, 64 four, 32 the whole 2,048."""
    import ptx

    assert [ptx.threads_an_sm(r) for r in (112, 80, 64, 32, 255)] == [512, 768, 1024, 2048, 256]


def test_ptxas_reports_a_kernel_s_registers_even_from_newer_ptx():
    """ptx.resources: ptxas assembles a hand-written kernel (x += 1 in double) for sm_90 and reports
    its registers and no spills; a .version newer than ptxas knows is set to the one it names. Needs
    CUDA's ptxas (CUDA_HOME/bin or PATH), else skipped."""
    import ptx

    if ptx.ptxas() is None:
        pytest.skip("no ptxas here (a CUDA toolkit: CUDA_HOME)")
    used = ptx.resources(ADD_ONE_PTX, (9, 0))
    assert 0 < used["registers"] <= 16 and used["spill_stores"] == used["spill_loads"] == 0
