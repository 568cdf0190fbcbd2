"""The colsim command (colsim.cli): every stage through it, progress, signals, bad input, exit statuses."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from colsim import io
from colsim.cli import main
from colsim.engine.state import ParticleState
from colsim.stages import analyse as analysis

from helpers import assert_cf_units, main_in, tiny_state_files


def _run_cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "colsim.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def test_progress_is_logged_every_tenth_of_the_steps_or_every_minute(caplog):
    """A slow run still logs: a line every 10 % of the steps, or after 60 s without one."""
    from colsim.cli.progress import progress_bar as _progress_bar
    from colsim.engine.records import StepDiagnostics

    now = [0.0]
    progress = _progress_bar(100, "collapse", interval_s=60.0, clock=lambda: now[0])
    fields = {name: 0 for name in StepDiagnostics.__dataclass_fields__}
    caplog.set_level("INFO", logger="colsim")
    for k, seconds in enumerate([1.0] * 12 + [70.0, 1.0], start=1):
        now[0] += seconds
        progress(StepDiagnostics(**{**fields, "step": k, "solver_status": "Solved", "solver_backend": "apgd"}))
    progress.close()
    steps = [r.getMessage().split(" of at most")[0].split()[-1] for r in caplog.records]
    assert steps == ["10", "13"]   # the 10 % mark, then the 70 s step; not every step after it
    assert "(82 s)" in caplog.records[-1].getMessage()


def test_all_stages_through_the_cli(tmp_path):
    """A tiny column (r0 = 1, a = 1) through pack, trim, collapse, analyse, export-vtk. (Its time
    is a benchmark's business, not a test's.)"""
    for args in (["pack", "--r0", "1", "--height", "1", "--seed", "3", "--output", "pack.nc"],
                 ["trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "column.nc"],
                 ["collapse", "--input", "column.nc", "--steps", "40", "--device", "auto", "--output", "collapse.nc"],
                 ["analyse", "--input", "collapse.nc", "--output", "analysis.nc"],
                 ["export-vtk", "--input", "collapse.nc", "--output-dir", "vtk"]):
        done = _run_cli(*args, cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        if "--device" in args:   # auto says which device it chose (a column this small: the CPU)
            assert "device auto: cpu (about " in done.stderr, done.stderr
    assert not list(tmp_path.glob("*.checkpoint*"))     # each stage removes its checkpoint (and frames) once its output is written
    result = io.open_dataset(tmp_path / "analysis.nc", io.ANALYSIS_KIND)
    for name, kind in (("pack.nc", io.STATE_KIND), ("column.nc", io.STATE_KIND),
                       ("collapse.nc", io.TRAJECTORY_KIND), ("analysis.nc", io.ANALYSIS_KIND)):
        assert_cf_units(io.open_dataset(tmp_path / name, kind))
    assert "scaled_time" in result.coords
    # the packing's file holds each step of the pour: the energy that fell to rest, the solver's work
    packing = io.open_dataset(tmp_path / "pack.nc", io.STATE_KIND)
    assert len(packing.step) == packing.attrs["steps"] and int(packing.step[-1]) == packing.attrs["steps"]
    assert packing.step_kinetic_energy.attrs["long_name"] and packing.step_solver_iterations.min() >= 0
    assert float(packing.step_kinetic_energy[-1]) < float(packing.step_kinetic_energy.max())
    for name in ("h_inf_over_r0", "runout_over_r0", "solid_fraction", "final_to_peak_kinetic_energy"):
        assert np.isfinite(result[name].values), name
        assert "units" in result[name].attrs and "long_name" in result[name].attrs
    assert 0 < float(result["h_inf_over_r0"]) <= 1.0 + 1e-9     # a collapse never grows
    assert float(result["runout_over_r0"]) >= 0
    # the checks: the study's tolerance (1 %) first, looser ones reach at least as far
    np.testing.assert_allclose(result.contact_tolerance.values, [0.01, 0.1, 0.5, 1.0])
    by_tolerance = result.runout_over_r0_by_tolerance.values
    assert by_tolerance[0] == pytest.approx(float(result["runout_over_r0"]))
    assert np.all(np.diff(by_tolerance) >= -1e-12)
    assert np.all(np.diff(result.mass_front_over_r0.values) >= 0)
    # the front frame by frame (issue 32, item 3): the radius holding 95 % of the mass. Inside the
    # cylinder at release (up to the overlap tolerance, 1 % of the smallest diameter; r0 = 1), the
    # deposit's own at the end, and outward as the grains spread (the same slack; six r0 = 3
    # collapses never moved it back at all)
    front = result[analysis.FRONT_MASS_VARIABLE]
    assert front.dims == ("time",) and front.attrs["units"] == "1" and "95%" in front.attrs["long_name"]
    slack = io.OVERLAP_TOLERANCE * 2 * float(io.open_dataset(tmp_path / "column.nc", io.STATE_KIND)["radius"].min())
    assert front.values[0] <= slack
    assert front.values[-1] == pytest.approx(float(result.mass_front_over_r0.sel(mass_share=0.95)))
    assert np.all(np.diff(front.values) >= -slack)
    for key in ("Conventions", "source", "history", "config", "seed"):
        assert key in result.attrs
    trajectory = io.open_dataset(tmp_path / "collapse.nc", io.TRAJECTORY_KIND)
    assert trajectory.sizes["step"] == 40 and set(trajectory["position"].dims) == {"time", "particle", "xyz"}
    assert (tmp_path / "vtk" / "collapse.pvd").exists()
    frames = list((tmp_path / "vtk").glob("*.vtu"))
    assert len(frames) == trajectory.sizes["time"]
    assert not list(tmp_path.glob("*.part")) and not list(tmp_path.glob("*.checkpoint"))
    # the packing's forces went through trim into the column file; at a small step `auto` starts
    # from them with APGD, and every step's back-end is in the trajectory
    column = io.open_dataset(tmp_path / "column.nc", io.STATE_KIND)
    assert column.sizes["contact"] > 0 and column["contact_first"].max() < column.sizes["particle"]
    done = _run_cli("collapse", "--input", "column.nc", "--steps", "50", "--duration", "0.5",
                    "--solver", "auto", "--output", "fast.nc", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    backends = io.open_dataset(tmp_path / "fast.nc", io.TRAJECTORY_KIND)["step_solver_backend"].values
    assert backends[0] == "apgd" and set(backends) <= {"apgd", "clarabel", "clarabel-fallback"}
    assert set(trajectory["step_solver_backend"].values) == {"clarabel"}
    # the back-end's settings, defaults included, are in the run's configuration: reproducible
    solver = json.loads(io.open_dataset(tmp_path / "fast.nc", io.TRAJECTORY_KIND).attrs["config"])["solver_settings"]
    assert solver["name"] == "auto" and solver["apgd"]["length_floor"] == 0.1 and solver["apgd"]["tolerance"] == 1e-5


# Runs the CLI with a hook on the checkpoint: once the first checkpoint is on disk, the process sends
# itself a signal. The signal lands mid-run on every machine, however fast or loaded (no race with
# the run's end, no polling). Ctrl-C is Python's own KeyboardInterrupt handler, as in a terminal: a
# process started in the background by a shell without job control inherits SIGINT ignored.
_SIGNAL_AFTER_FIRST_CHECKPOINT = """
import os, signal, sys
import colsim.stages.collapse as collapse
from colsim.cli import main
signal.signal(signal.SIGINT, signal.default_int_handler)
save = collapse.save_checkpoint
def save_then_signal(*args, **kwargs):
    save(*args, **kwargs)
    os.kill(os.getpid(), signal.{name})
collapse.save_checkpoint = save_then_signal
sys.exit(main(sys.argv[1:]))
"""


def _signalled_at_first_checkpoint(name: str, *args, cwd):
    """Run `colsim *args` and send it signal `name` just after it wrote its first checkpoint."""
    script = _SIGNAL_AFTER_FIRST_CHECKPOINT.format(name=name)
    return subprocess.run([sys.executable, "-c", script, *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_killed_collapse_leaves_no_result_and_resumes(tmp_path):
    assert _run_cli("pack", "--r0", "1", "--height", "1.5", "--seed", "4", "--output", "pack.nc", cwd=tmp_path).returncode == 0
    assert _run_cli("trim", "--input", "pack.nc", "--aspect-ratio", "1.5", "--output", "column.nc", cwd=tmp_path).returncode == 0
    common = ["collapse", "--input", "column.nc", "--steps", "60", "--checkpoint-every", "5"]
    assert _run_cli(*common, "--output", "whole.nc", cwd=tmp_path).returncode == 0
    killed = _signalled_at_first_checkpoint("SIGKILL", *common, "--output", "killed.nc", cwd=tmp_path)
    assert killed.returncode == -signal.SIGKILL
    assert (tmp_path / "killed.nc.checkpoint").exists() and not (tmp_path / "killed.nc").exists()
    assert (tmp_path / "killed.nc.checkpoint.frames").exists()
    done = _run_cli(*common, "--output", "killed.nc", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "resuming from the checkpoint" in done.stderr
    whole = io.open_dataset(tmp_path / "whole.nc", io.TRAJECTORY_KIND)
    resumed = io.open_dataset(tmp_path / "killed.nc", io.TRAJECTORY_KIND)
    assert int(resumed.attrs["resumed_from_step"]) == 5
    np.testing.assert_allclose(resumed["position"].values, whole["position"].values, rtol=0, atol=1e-12)
    assert not list(tmp_path.glob("killed.nc.checkpoint*"))


def test_ctrl_c_keeps_the_checkpoint_and_says_how_to_resume(tmp_path):
    """Ctrl-C (SIGINT) on a collapse: one line, no traceback, the checkpoint kept, exit 130."""
    assert _run_cli("pack", "--r0", "1", "--height", "1.5", "--seed", "4", "--output", "pack.nc", cwd=tmp_path).returncode == 0
    assert _run_cli("trim", "--input", "pack.nc", "--aspect-ratio", "1.5", "--output", "column.nc", cwd=tmp_path).returncode == 0
    done = _signalled_at_first_checkpoint("SIGINT", "collapse", "--input", "column.nc", "--steps", "60",
                                          "--checkpoint-every", "2", "--output", "c.nc", cwd=tmp_path)
    assert done.returncode == 130, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines()[-1] == ("colsim collapse: interrupted; the checkpoint c.nc.checkpoint is kept: "
                                                    "run the same command again to resume from it")
    assert (tmp_path / "c.nc.checkpoint").exists() and not (tmp_path / "c.nc").exists()


@pytest.mark.parametrize("args, message", [
    (["trim", "--input", "missing.nc", "--aspect-ratio", "1", "--output", "out.nc"], "does not exist"),
    (["trim", "--input", "foreign.nc", "--aspect-ratio", "1", "--output", "out.nc"], "not a readable netCDF"),
    (["trim", "--input", "pack.nc", "--aspect-ratio", "0", "--output", "out.nc"], "must be > 0, got 0"),
    (["trim", "--input", "pack.nc", "--aspect-ratio", "40", "--output", "out.nc"], "too short"),
    (["collapse", "--input", "pack.nc", "--output", "out.nc"], "not a trimmed column"),
    (["collapse", "--input", "column.nc", "--mu", "-0.1", "--output", "out.nc"], "must be >= 0, got -0.1"),
    (["collapse", "--input", "column.nc", "--mu-r", "-1", "--output", "out.nc"], "must be >= 0, got -1"),
    (["pack", "--r0", "0.2", "--height", "1", "--output", "out.nc"], "smaller than the largest particle"),
    (["analyse", "--input", "column.nc", "--output", "out.nc"], "expected 'collapse-trajectory'"),
    (["trim", "--input", "pack.nc", "--aspect-ratio", "abc", "--output", "out.nc"], "must be a number, got 'abc'"),
    (["pack", "--height", "1", "--seed", "x", "--output", "out.nc"], "must be an integer, got 'x'"),
    (["collapse", "--input", "column.nc", "--solver", "simplex", "--output", "out.nc"], "invalid choice: 'simplex'"),
])
def test_bad_input_gives_one_clear_error_and_no_output(tmp_path, capsys, args, message):
    state = ParticleState.at_rest([[0, 0, 0.25], [0, 0, 0.75]], [0.25, 0.25])
    io.write_state(tmp_path / "pack.nc", state, {**io.global_attributes(io.STATE_KIND, "t", {}), "r0": 1.0})
    io.write_state(tmp_path / "column.nc", state,
                   {**io.global_attributes(io.STATE_KIND, "t", {}), "r0": 1.0, "h0": 1.0, "aspect_ratio": 1.0,
                    "solid_fraction": 0.1})
    (tmp_path / "foreign.nc").write_text("not netCDF")
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        code = main(args)
    except SystemExit as exit_:          # argparse rejects the value itself
        code = exit_.code
    finally:
        os.chdir(cwd)
    assert code == 2
    err = capsys.readouterr().err
    assert message in err
    assert len([line for line in err.splitlines() if "error" in line]) == 1
    assert "_positive" not in err and "_integer" not in err
    assert not (tmp_path / "out.nc").exists()


@pytest.mark.parametrize("args", [
    ["collapse", "--input", "column.nc", "--steps", "12", "--output", "/proc/col.nc"],
    ["pack", "--r0", "1", "--height", "1", "--output", "/proc/pack.nc"],
    ["trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "pack.nc/column.nc"],
    ["analyse", "--input", "column.nc", "--output", "/proc/analysis.nc"],
    ["collect", "column.nc", "--output", "summary.nc", "--csv", "/proc/summary.csv"],
    ["plot", "--summary", "column.nc", "--output-dir", "/proc/figures"],
    ["export-vtk", "--input", "column.nc", "--output-dir", "pack.nc"],
])
def test_unwritable_output_fails_before_the_work(tmp_path, capsys, monkeypatch, args):
    """Issue 16, defect 2: every stage checks that it can write its outputs before it computes
    (not one step of the collapse or the packing is taken), one line, exit 2, no file."""
    tiny_state_files(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())

    def no_step(*args, **kwargs):
        raise AssertionError("a step was taken before the outputs were checked")
    monkeypatch.setattr("colsim.engine.stepper.step", no_step)
    assert main_in(tmp_path, args) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "error: cannot write" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_a_column_of_less_than_a_layer_is_an_error(tmp_path, capsys):
    """Issue 16, defect 3: a cut below the smallest diameter (here h0 = 0.05) is refused naming h0 and
    the smallest diameter, and writes nothing."""
    tiny_state_files(tmp_path)
    assert main_in(tmp_path, ["trim", "--input", "pack.nc", "--aspect-ratio", "0.05", "--output", "x.nc"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "h0 = 0.05 leaves 0 spheres" in err and "smallest diameter 0.5" in err
    assert not (tmp_path / "x.nc").exists()


def test_status_lists_what_is_done_and_what_is_in_progress(tmp_path, capsys):
    """`colsim status FOLDER`: the finished packings and collapses counted, one row a checkpoint
    (its run folder, stage and last step), and a clear error for a folder that is not there."""
    from colsim.engine.records import Carry
    from colsim.io.checkpoint import save_checkpoint

    run = tmp_path / "r0_2" / "seed_1" / "pack_x" / "a_1" / "mu_r_0.12" / "run_y"
    run.mkdir(parents=True)
    (run.parents[2] / "packing.nc").write_bytes(b"")
    state = ParticleState.at_rest(np.array([[0.0, 0.0, 0.2], [0.5, 0.0, 0.2]]), np.full(2, 0.2))
    save_checkpoint(run / "collapse.nc.checkpoint", "abc", state, [(0, state)], [], Carry(), 4.0, 3.0)
    assert main(["status", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1 packing and 0 collapses done, 1 in progress" in out
    assert "| r0_2/seed_1/pack_x/a_1/mu_r_0.12/run_y | collapse | 2 | -1 |" in out
    # issue 45.6: a FIFO named *.checkpoint is skipped (opening it would block), a junk file is named
    os.mkfifo(run.parent / "fifo.checkpoint")
    (run.parent / "junk.checkpoint").write_bytes(b"not an archive")
    assert main(["status", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "2 in progress" in out and "not a colsim checkpoint" in out and "pickle" not in out
    assert main(["status", str(tmp_path / "nowhere")]) == 2
    assert "is not a folder" in capsys.readouterr().err
