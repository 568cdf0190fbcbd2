"""A collapse's checkpoint (colsim.io.checkpoint): what is saved comes back exactly; a checkpoint of
other inputs, a damaged or foreign file, or an impossible saved state is refused, never taken for this
run's nor replaced; the commits of every segment are kept."""
import logging
import os
import re
from dataclasses import replace

import numpy as np
import pytest

from colsim.engine.records import Carry, StepDiagnostics
from colsim.engine.state import ParticleState
from colsim.engine.warm_start import WarmStart
from colsim.io.checkpoint import (FRAMES_HEADER, CheckpointError, check_checkpoint_path, checkpoint_summary,
                                  frames_path, load_checkpoint, load_packing_checkpoint, remove_checkpoint,
                                  save_checkpoint, save_packing_checkpoint)
from colsim.io.provenance import source_commit


def _diagnostics(step: int) -> StepDiagnostics:
    numbers = {name: step + 0.5 for name in StepDiagnostics.__dataclass_fields__}
    integers = ("step", "n_contacts", "n_active", "solver_iterations", "friction_iterations", "redone",
                "missed_contacts")
    return StepDiagnostics(**{**numbers, **{name: step for name in integers},
                              "solver_status": "Solved", "solver_backend": "apgd"})


def _run():
    rng = np.random.default_rng(5)
    apart = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [1.0, 1.0, 1.0]])  # no overlap, above the floor
    state = ParticleState(apart + rng.uniform(-0.1, 0.1, (4, 3)), rng.normal(size=(4, 3)), rng.normal(size=(4, 3)),
                          rng.uniform(0.1, 0.2, 4), 2.5, 0.3)
    frames = [(0, ParticleState.at_rest(apart, state.radius, 2.5)), (10, state)]
    warm = WarmStart(np.array([0, 1]), np.array([1, -1]), np.array([0, 1]), rng.normal(size=(2, 3)),
                     rng.normal(size=(2, 3)))
    return state, frames, [_diagnostics(1), _diagnostics(2)], Carry(warm, 0.01)


def test_a_checkpoint_comes_back_exactly(tmp_path):
    state, frames, diagnostics, carry = _run()
    path = tmp_path / "run.checkpoint.npz"
    save_checkpoint(path, "abc", state, frames, diagnostics, carry, 12.5, 20.25)
    saved = load_checkpoint(path, "abc")
    for name in ("position", "velocity", "angular_velocity", "radius"):
        np.testing.assert_array_equal(getattr(saved["state"], name), getattr(state, name))
    assert saved["state"].time == state.time and saved["state"].density == state.density
    assert [k for k, _ in saved["frames"]] == [0, 10]
    np.testing.assert_array_equal(saved["frames"][0][1].position, frames[0][1].position)
    assert saved["diagnostics"] == diagnostics
    assert saved["carry"].margin == 0.01 and saved["elapsed"] == 12.5 and saved["cpu"] == 20.25
    for name in ("i", "j", "family", "force", "rolling"):
        np.testing.assert_array_equal(getattr(saved["carry"].warm_start, name), getattr(carry.warm_start, name))


@pytest.mark.parametrize("first", [True, False])
def test_a_checkpoint_the_disk_cannot_hold_leaves_no_orphan_frames(tmp_path, monkeypatch, first):
    """Issue 80.7: a full disk at the first checkpoint left a frames file that no checkpoint lists.
    Now the error comes back and the frames file goes with it; at a later checkpoint the last one and
    its frames stay, and the run resumes from them."""
    import errno
    from colsim.io import checkpoint

    state, frames, diagnostics, carry = _run()
    path = tmp_path / "run.checkpoint.npz"
    if not first:
        save_checkpoint(path, "abc", state, frames[:1], diagnostics, carry, 1.0)

    def full_disk(target, arrays):
        raise OSError(errno.ENOSPC, "No space left on device", str(target))

    monkeypatch.setattr(checkpoint, "_write", full_disk)
    with pytest.raises(OSError, match="No space left"):
        save_checkpoint(path, "abc", state, frames, diagnostics, carry, 2.0)
    monkeypatch.undo()
    if first:
        assert sorted(p.name for p in tmp_path.iterdir()) == []
    else:
        assert [k for k, _ in load_checkpoint(path, "abc")["frames"]] == [0]


def test_a_checkpoint_from_before_the_matching_and_check_times_resumes(tmp_path):
    """A checkpoint written before StepDiagnostics timed the matching and the overlap check (the
    calibration's, say) still resumes: those two come back as NaN, every other field exactly."""
    state, frames, diagnostics, carry = _run()
    path = tmp_path / "old.checkpoint.npz"
    save_checkpoint(path, "abc", state, frames, diagnostics, carry, 1.0)
    with np.load(path, allow_pickle=False) as archive:
        older = {name: archive[name] for name in archive.files
                 if name not in ("diagnostic_matching_time", "diagnostic_check_time")}
    np.savez(path, **older)
    saved = load_checkpoint(path, "abc")["diagnostics"]
    assert all(np.isnan(d.matching_time) and np.isnan(d.check_time) for d in saved)
    for before, after in zip(diagnostics, saved):
        assert after == replace(before, matching_time=after.matching_time, check_time=after.check_time)


def test_no_warm_start_and_no_margin_come_back_as_none(tmp_path):
    state, frames, diagnostics, _ = _run()
    save_checkpoint(tmp_path / "c.npz", "abc", state, frames, diagnostics, Carry(), 0.0)
    carry = load_checkpoint(tmp_path / "c.npz", "abc")["carry"]
    assert carry.warm_start is None and carry.margin is None


def test_another_run_s_a_damaged_or_a_foreign_file_is_refused(tmp_path):
    """Issue 45.2: colsim reads past or replaces nothing it did not write for this run: another run's
    checkpoint, a damaged one, a file that is no checkpoint (notes.txt) and a FIFO are refused with a
    line saying what to do; an absent path is simply no checkpoint."""
    state, frames, diagnostics, carry = _run()
    path = tmp_path / "c.npz"
    save_checkpoint(path, "abc", state, frames, diagnostics, carry, 1.0)
    with pytest.raises(CheckpointError, match="belongs to another run"):
        load_checkpoint(path, "other settings")
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(CheckpointError, match="not a colsim checkpoint"):
        load_checkpoint(path, "abc")
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    with pytest.raises(CheckpointError, match="not a colsim checkpoint"):
        check_checkpoint_path(notes)
    assert notes.read_text() == "my notes\n"
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(CheckpointError, match="not a regular file"):
        check_checkpoint_path(fifo)     # refused without opening it (which would block)
    assert load_checkpoint(tmp_path / "absent.npz", "abc") is None
    assert load_checkpoint(None, "abc") is None


def test_an_edited_state_is_refused_like_a_bad_column(tmp_path):
    """Issue 45.4: a checkpoint edited to put two spheres on one spot (or a NaN) passes the same
    checks as a fresh column before it is resumed."""
    state, frames, diagnostics, carry = _run()
    for spoil, words in ((lambda s: s.position.__setitem__(1, s.position[0]), "overlap"),
                         (lambda s: s.position.__setitem__((2, 0), np.nan), "non-finite")):
        bad = state.copy()
        spoil(bad)
        save_checkpoint(tmp_path / "e.npz", "abc", bad, frames, diagnostics, carry, 1.0)
        with pytest.raises(CheckpointError, match=words):
            load_checkpoint(tmp_path / "e.npz", "abc")


@pytest.mark.parametrize("spoil, words", [
    (lambda warm: warm.i.__setitem__(0, 10**9), "a contact names a sphere outside 0..3"),
    (lambda warm: warm.j.__setitem__(0, -10**9), "a contact names a sphere outside 0..3"),
    (lambda warm: warm.force.__setitem__((1, 2), np.inf), "a contact force is not finite"),
])
def test_a_warm_start_naming_spheres_the_run_does_not_hold_is_refused(tmp_path, spoil, words):
    """Issue 80.6: a checkpoint whose warm-start indices were 10^9 was resumed silently; its forces
    by pair are now checked as an input file's contact forces are."""
    state, frames, diagnostics, carry = _run()
    spoil(carry.warm_start)
    save_checkpoint(tmp_path / "w.npz", "abc", state, frames, diagnostics, carry, 1.0)
    with pytest.raises(CheckpointError, match="checkpoint .*w.npz: its warm start: " + re.escape(words)):
        load_checkpoint(tmp_path / "w.npz", "abc")


def test_a_small_checkpoint_declaring_gigabytes_is_refused_before_it_is_read(tmp_path):
    """Issue 80.2: every file colsim opens is bounded before it is decoded: an .npz whose array
    declares 80 GB in a few bytes is refused, never allocated."""
    import io as bytes_io
    import zipfile

    header = bytes_io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**10,)})
    path = tmp_path / "huge.checkpoint"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("fingerprint.npy", header.getvalue() + bytes(8))
    with pytest.raises(CheckpointError, match="fingerprint.npy declares 80,000,000,000 bytes but holds"):
        load_checkpoint(path, "abc")


def test_every_segments_commit_is_kept(tmp_path, caplog):
    """Issue 45.4: a run resumed by other code is resumed (the fingerprint holds the inputs and
    settings, which decide the steps), with a warning, and lists the commit of every segment."""
    state, frames, diagnostics, carry = _run()
    path = tmp_path / "c.npz"
    save_checkpoint(path, "abc", state, frames, diagnostics, carry, 1.0, commits=["0123abc (an earlier segment)"])
    caplog.set_level(logging.WARNING, logger="colsim")
    saved = load_checkpoint(path, "abc")
    assert saved["commits"] == ["0123abc (an earlier segment)", source_commit()]
    assert "written by other code (0123abc" in caplog.text


def test_a_checkpoint_without_cpu_time_resumes_with_it_unknown(tmp_path):
    """A checkpoint written before CPU time was saved: its run resumes, its CPU time over all
    segments is NaN (unknown), not the last segment's taken for the whole."""
    state, frames, diagnostics, carry = _run()
    path = tmp_path / "old.npz"
    save_checkpoint(path, "abc", state, frames, diagnostics, carry, 12.5)
    with np.load(path) as archive:
        arrays = {name: archive[name] for name in archive.files if name != "cpu"}
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)
    saved = load_checkpoint(path, "abc")
    assert saved["elapsed"] == 12.5 and np.isnan(saved["cpu"])
    assert saved["diagnostics"] == diagnostics


def test_a_packing_checkpoint_keeps_its_steps_diagnostics(tmp_path):
    """A packing's checkpoint holds the diagnostics of its steps so far, so that the packing's file
    has every step of a pour that spanned segments; one written before it held them resumes with
    none (the steps from the resumed one on)."""
    state, _, diagnostics, _ = _run()
    loop = {"steps": 2, "last": True}
    path = tmp_path / "pack.npz"
    save_packing_checkpoint(path, "abc", state, None, None, loop, 3.0, 4.0, diagnostics)
    saved = load_packing_checkpoint(path, "abc")
    assert saved["diagnostics"] == diagnostics and int(saved["loop"]["steps"]) == 2
    with np.load(path) as archive:
        arrays = {name: archive[name] for name in archive.files if not name.startswith("diagnostic_")}
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)
    assert load_packing_checkpoint(path, "abc")["diagnostics"] == []


def test_a_checkpoints_summary_names_its_stage_last_step_and_cost(tmp_path):
    """The summary a study's status shows: a collapse's or a packing's last step, simulated time,
    last kinetic energy, mean wall seconds of its last 10 steps and the seconds so far; a packing
    checkpoint without a step record (written before packings kept one) gives step -1 and NaN."""
    state, frames, _, carry = _run()
    steps = [_diagnostics(k) for k in range(1, 13)]
    save_checkpoint(tmp_path / "c", "abc", state, frames, steps, carry, 12.5, 20.25)
    found = checkpoint_summary(tmp_path / "c")
    assert found == {"stage": "collapse", "spheres": 4, "step": 12, "time": 0.3, "kinetic_energy": 12.5,
                     "seconds_per_step": np.mean([k + 0.5 for k in range(3, 13)]), "elapsed": 12.5, "cpu": 20.25}
    save_packing_checkpoint(tmp_path / "p", "abc", state, None, None, {"steps": 7}, 3.0, 4.0)
    found = checkpoint_summary(tmp_path / "p")
    assert found["stage"] == "packing" and found["step"] == -1 and np.isnan(found["kinetic_energy"])
    assert (found["spheres"], found["elapsed"], found["cpu"]) == (4, 3.0, 4.0)


def _later(state: ParticleState, dt: float) -> ParticleState:
    return ParticleState(state.position + dt * state.velocity, state.velocity, state.angular_velocity, state.radius,
                         state.density, state.time + dt)


def test_each_frame_is_written_once_beside_the_checkpoint(tmp_path):
    """A collapse's frames go to <checkpoint>.frames, each appended by the first checkpoint after it:
    a later checkpoint writes only its new frames (the records already there keep their bytes) and
    the archive lists them; all come back exactly."""
    state, frames, diagnostics, carry = _run()
    path = tmp_path / "c.checkpoint"
    save_checkpoint(path, "abc", state, frames, diagnostics, carry, 1.0)
    first = frames_path(path).read_bytes()
    record = (len(first) - FRAMES_HEADER) // 2
    assert record == 8 * (2 + 9 * state.n)
    more = frames + [(20, _later(state, 0.01)), (30, _later(state, 0.02))]
    save_checkpoint(path, "abc", more[-1][1], more, diagnostics, carry, 2.0)
    second = frames_path(path).read_bytes()
    assert len(second) == FRAMES_HEADER + 4 * record and second.startswith(first)
    with np.load(path) as archive:
        assert "frame_position" not in archive.files and list(archive["frame_step"]) == [0, 10, 20, 30]
    saved = load_checkpoint(path, "abc")
    assert [k for k, _ in saved["frames"]] == [0, 10, 20, 30]
    for (_, got), (_, put) in zip(saved["frames"], more):
        assert got.time == put.time
        for name in ("position", "velocity", "angular_velocity", "radius"):
            np.testing.assert_array_equal(getattr(got, name), getattr(put, name))
    remove_checkpoint(path)
    assert not path.exists() and not frames_path(path).exists()


def test_frames_past_the_checkpoint_are_cut_and_a_fresh_run_starts_them_over(tmp_path):
    """A run killed while appending frames (or after appending, before its archive was renamed in)
    leaves records the checkpoint does not list: loading the checkpoint cuts them off, and the next
    checkpoint appends after the listed ones. With no checkpoint, the frames file is removed: the run
    starts over."""
    state, frames, diagnostics, carry = _run()
    path = tmp_path / "c.checkpoint"
    save_checkpoint(path, "abc", state, frames, diagnostics, carry, 1.0)
    listed = frames_path(path).read_bytes()
    with open(frames_path(path), "ab") as handle:
        handle.write(np.arange(2 + 9 * state.n + 13, dtype="<f8").tobytes())   # a record and a part of one
    assert len(load_checkpoint(path, "abc")["frames"]) == 2
    assert frames_path(path).read_bytes() == listed
    path.unlink()
    assert load_checkpoint(path, "abc") is None and not frames_path(path).exists()


def test_missing_or_foreign_frames_are_refused(tmp_path):
    """Issue 45.2 for the frames file: a checkpoint whose frames file is gone, short or another run's
    is refused (remove it to start over); a file that is not colsim's at the frames path is neither
    read nor replaced."""
    state, frames, diagnostics, carry = _run()
    path = tmp_path / "c.checkpoint"
    save_checkpoint(path, "abc", state, frames, diagnostics, carry, 1.0)
    whole = frames_path(path).read_bytes()
    frames_path(path).write_bytes(whole[:-8])
    with pytest.raises(CheckpointError, match="frames file .* short of its 2 frames"):
        load_checkpoint(path, "abc")
    frames_path(path).unlink()
    with pytest.raises(CheckpointError, match="frames file .* missing"):
        load_checkpoint(path, "abc")
    save_checkpoint(tmp_path / "other.checkpoint", "another run", state, frames, diagnostics, carry, 1.0)
    frames_path(tmp_path / "other.checkpoint").rename(frames_path(path))
    with pytest.raises(CheckpointError, match="frames file .* another run's"):
        load_checkpoint(path, "abc")
    frames_path(path).unlink()
    frames_path(path).write_text("my notes\n")
    with pytest.raises(CheckpointError, match="not a colsim frames file"):
        check_checkpoint_path(path)
    with pytest.raises(CheckpointError, match="not a colsim frames file"):
        load_checkpoint(path, "abc")
    assert frames_path(path).read_text() == "my notes\n"
    path.unlink()
    frames_path(path).write_bytes(b"")    # a run killed as it began the file: replaced, nothing lost
    assert load_checkpoint(path, "abc") is None and not frames_path(path).exists()


def test_a_checkpoint_with_its_frames_inside_still_resumes(tmp_path):
    """A checkpoint written before the frames file (the frames as arrays in the archive) resumes with
    its frames, and its next checkpoint writes them all to the frames file."""
    state, frames, diagnostics, carry = _run()
    path = tmp_path / "old.checkpoint"
    save_checkpoint(path, "abc", state, frames, diagnostics, carry, 1.0)
    with np.load(path) as archive:
        arrays = dict(archive)
    for name in ("position", "velocity", "angular_velocity"):
        arrays[f"frame_{name}"] = np.stack([getattr(f, name) for _, f in frames])
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)
    frames_path(path).unlink()
    saved = load_checkpoint(path, "abc")
    np.testing.assert_array_equal(saved["frames"][1][1].velocity, frames[1][1].velocity)
    save_checkpoint(path, "abc", state, saved["frames"], diagnostics, carry, 2.0)
    assert len(load_checkpoint(path, "abc")["frames"]) == 2
