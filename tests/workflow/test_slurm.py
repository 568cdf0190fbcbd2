"""The cluster path: the tiny study through a real one-node SLURM cluster and the project's profile.

A SLURM cluster (munged, slurmctld, slurmd; tests/slurm_cluster.py) is started on this machine for
the module and stopped, by pid, at its end. In a copy of the workflow the tests run what docs/slurm.md
shows, with the two options this accounting-free cluster needs:

    snakemake --executor slurm --workflow-profile workflow/profiles/slurm all \
        --configfile config/tiny.yaml \
        --slurm-status-command squeue --slurm-init-seconds-before-status-checks 2

and check that every job but the local rules ran as a SLURM job, that results/tiny/summary.nc holds the
same numbers as a local run of the tiny study (`snakemake -j2 all --configfile config/tiny.yaml`)
and that the figures come out; and that a job that fails on the cluster (a packing allowed one
step, so `colsim pack` stops with "not at rest") fails the run, names the job's log and leaves no
result behind. About 2-3 minutes on 2 cores.

Needs root and Debian's slurmctld, slurmd, slurm-client and munge (`.ci/run` installs them).
Without them the tests are skipped, except in CI (CI=true), where anything short of a running
cluster fails.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from slurm_cluster import PACKAGES, ClusterError, SlurmCluster, missing_programs
from helpers import FIGURES, SUMMARY_VARIABLES, TINY, copy_workflow

pytestmark = pytest.mark.slurm

IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")
# the command of docs/slurm.md, with what a cluster without slurmdbd needs
SLURM_COMMAND = ("--executor", "slurm", "--workflow-profile", "workflow/profiles/slurm", "all",
                 "--configfile", "config/tiny.yaml")
TEST_CLUSTER_OPTIONS = ("--slurm-status-command", "squeue",
                        "--slurm-init-seconds-before-status-checks", "2")
LOCAL_RULES = {"all", "paraview", "study_config", "packing_settings", "run_settings"}
SLURM_JOBS = 13          # pack 1, trim 2, collapse 4, analyse 4, collect, plot


def unavailable(reason: str):
    if IN_CI:
        pytest.fail(f"CI must run the SLURM tests, but {reason}")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    if os.geteuid() != 0:
        unavailable("the test cluster needs root (slurmd starts jobs as their user)")
    missing = missing_programs()
    if missing:
        unavailable(f"{', '.join(missing)} not installed: apt-get install -y "
                    f"--no-install-recommends {' '.join(PACKAGES)} (or run .ci/run)")
    directory = tmp_path_factory.mktemp("slurm")
    try:
        with SlurmCluster(directory) as running:
            yield running
    except ClusterError as error:
        pytest.fail(f"the SLURM test cluster did not start: {error}")


def snakemake(cluster: SlurmCluster | None, directory: Path, *arguments, timeout=900):
    """snakemake in `directory`, with colsim's interpreter on PATH (the jobs inherit it via sbatch)."""
    env = cluster.env() if cluster else dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env.setdefault("MPLBACKEND", "Agg")
    return subprocess.run([sys.executable, "-m", "snakemake", *arguments], cwd=directory, env=env,
                          capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)


def jobs_run_in(cluster: SlurmCluster, directory: Path) -> list[tuple[str, str]]:
    """(state, comment) of every SLURM job submitted from `directory` (squeue keeps them MinJobAge)."""
    listed = subprocess.run(["squeue", "--noheader", "--states=all", "--format=%T|%Z|%k"],
                            env=cluster.env(), capture_output=True, text=True, timeout=30)
    assert listed.returncode == 0, listed.stderr
    jobs = []
    for line in listed.stdout.splitlines():
        state, workdir, comment = line.split("|", 2)
        if Path(workdir) == directory:
            jobs.append((state, comment))
    return jobs


def failure_text(result) -> str:
    return f"exit {result.returncode}\n--- stdout\n{result.stdout[-3000:]}\n--- stderr\n{result.stderr[-6000:]}"


@pytest.fixture(scope="module")
def slurm_study(cluster, tmp_path_factory):
    directory = copy_workflow(tmp_path_factory.mktemp("slurm_study")).resolve()
    result = snakemake(cluster, directory, *SLURM_COMMAND, *TEST_CLUSTER_OPTIONS)
    assert result.returncode == 0, failure_text(result) + "\n" + cluster.log_tails()
    return directory, result


@pytest.fixture(scope="module")
def local_study(tmp_path_factory):
    directory = copy_workflow(tmp_path_factory.mktemp("local_study"))
    result = snakemake(None, directory, "-j2", "all", "--configfile", "config/tiny.yaml")
    assert result.returncode == 0, failure_text(result)
    return directory


def test_every_job_but_the_local_rules_ran_on_slurm(cluster, slurm_study):
    directory, result = slurm_study
    jobs = jobs_run_in(cluster, directory)
    assert len(jobs) == SLURM_JOBS, jobs
    assert all(state == "COMPLETED" for state, _ in jobs), jobs
    # the plugin writes "rule_<name>_wildcards_..." as each job's comment
    rules = sorted(comment.split("_wildcards")[0].removeprefix("rule_") for _, comment in jobs)
    assert rules == sorted(["pack"] + ["trim"] * 2 + ["collapse"] * 4 + ["analyse"] * 4
                           + ["collect", "plot"]), rules
    assert not LOCAL_RULES & set(rules)
    assert "Finished" in result.stderr and "100%" in result.stderr


def test_summary_matches_a_local_run(slurm_study, local_study):
    xr = pytest.importorskip("xarray")
    directory, _ = slurm_study
    on_slurm = xr.load_dataset(directory / TINY / "summary.nc")
    local = xr.load_dataset(local_study / TINY / "summary.nc")
    assert dict(on_slurm.sizes) == dict(local.sizes) == {"aspect_ratio": 2, "mu_r": 2, "seed": 1,
                                                         "contact_tolerance": 4, "mass_share": 3}
    assert set(on_slurm.data_vars) == set(local.data_vars)
    for name in on_slurm.data_vars:
        assert on_slurm[name].attrs.get("units") == local[name].attrs.get("units"), name
        if name == "wall_time" or not np.issubdtype(on_slurm[name].dtype, np.number):
            continue
        np.testing.assert_allclose(on_slurm[name].values, local[name].values, rtol=1e-9, atol=0,
                                   err_msg=name)
    for name in SUMMARY_VARIABLES:
        assert np.all(np.isfinite(on_slurm[name].values)), name
    table = (directory / TINY / "summary.csv").read_text().splitlines()
    assert len(table) == len((local_study / TINY / "summary.csv").read_text().splitlines())


def test_figures_logs_and_benchmarks_as_in_a_local_run(slurm_study, local_study):
    directory, _ = slurm_study
    for name in FIGURES:
        path = directory / TINY / "figures" / f"{name}.png"
        assert path.is_file() and path.stat().st_size > 1000, name
    assert (directory / TINY / "study_config.yaml").is_file()

    def listing(root: Path, pattern: str) -> list[str]:
        return sorted(str(p.relative_to(root)) for p in (root / "results").rglob(pattern))

    for pattern in ("*.nc", "*.png", "*.log", "*.tsv", "*.csv", "*.yaml"):
        assert listing(directory, pattern) == listing(local_study, pattern), pattern
    assert not list((directory / "results").rglob("*.checkpoint"))


def test_a_job_that_fails_on_slurm_fails_the_run_naming_its_log(cluster, tmp_path):
    directory = copy_workflow(tmp_path).resolve()
    # one packing step cannot bring the spheres to rest: `colsim pack` exits non-zero at run time
    (directory / "fail.yaml").write_text("pack:\n  max_steps: 1\n")
    result = snakemake(cluster, directory, *SLURM_COMMAND, "fail.yaml", *TEST_CLUSTER_OPTIONS)
    output = result.stdout + result.stderr
    assert result.returncode != 0, failure_text(result)
    logs = list((directory / "results" / "logs" / "r0_1" / "seed_1").glob("pack_*/pack.log"))
    assert len(logs) == 1, failure_text(result)
    log = logs[0].relative_to(directory).as_posix()
    assert log in output, failure_text(result)
    assert "not at rest" in (directory / log).read_text()
    assert "FAILED" in output, failure_text(result)
    states = [state for state, _ in jobs_run_in(cluster, directory)]
    assert states == ["FAILED", "FAILED"], states   # the pack and its retry (profile: retries: 1)
    results = directory / "results"
    assert not list((results / "r0_1" / "seed_1").glob("pack_*/packing.nc"))
    assert not (results / "summary.nc").exists() and not (results / "summary.csv").exists()
    assert not list(results.rglob("*.png")) and not list(results.rglob("*.nc"))
