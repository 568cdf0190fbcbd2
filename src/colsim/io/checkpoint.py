"""The checkpoints of a collapse and of a packing: numpy .npz archives of plain arrays, read with
allow_pickle=False: loading one can run no code, and its fingerprint (the run's inputs and
settings) is compared before anything else in it is used. Written to a temporary name, then renamed.

A checkpoint path holds this run's checkpoint or nothing: a file there that is not a colsim
checkpoint, or that is another run's, is refused (:class:`CheckpointError`), never read past or
replaced. A resumed state passes the same checks as a fresh column (finite, no overlap beyond the
stepper's tolerance). Each checkpoint lists the commits of the code of every segment so far
(`commits`), so that a run resumed by other code says so in its output.

A collapse's holds the state, the steps' diagnostics, and the warm start and margin carried to the
next step, and lists the frames so far, which lie beside it in `<checkpoint>.frames` (:func:`frames_path`):
each frame is appended there once, by the first checkpoint after it, so a checkpoint costs the same at
the end of a run as at its start. The archive is the authority: loading it truncates the
frames file to the frames it lists (a killed run may have appended more), and a run that starts
without a checkpoint starts that file over. A packing's holds the state, the steps' diagnostics and
what its filling loop carries (:func:`save_packing_checkpoint`). :func:`remove_checkpoint` removes both
files.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..engine.records import TEXT_DIAGNOSTICS, Carry, StepDiagnostics
from ..engine.state import ParticleState
from ..engine.warm_start import WarmStart
from . import checks
from .files import InputError, atomic_path
from .provenance import source_commit
from .state_file import check_geometry

log = logging.getLogger(__name__)

STATE_FIELDS = ("position", "velocity", "angular_velocity")
WARM_FIELDS = ("i", "j", "family", "force", "rolling")

#: the first bytes of a collapse's frames file; its header (the magic, the run's fingerprint and the
#: spheres' count, padded) takes FRAMES_HEADER bytes, then one record a frame: float64 step, time,
#: then position, velocity and angular velocity (n, 3) each
FRAMES_MAGIC = b"colsim collapse frames 1\n"
FRAMES_HEADER = 4096


class CheckpointError(InputError):
    """A checkpoint path that holds something colsim must not read past or replace."""


def save_checkpoint(path, fingerprint, state, frames, diagnostics, carry, elapsed, cpu=float("nan"), commits=()):
    """A collapse after its last step: `elapsed` and `cpu`, the wall and CPU seconds spent so far;
    `commits`, those of the earlier segments (this one's is added). A first checkpoint that cannot be
    written (a full disk) leaves no frames file behind: no checkpoint lists its frames."""
    first = not Path(path).exists()
    try:
        _append_frames(path, fingerprint, state.n, frames)
        arrays = _common_arrays(fingerprint, state, carry.warm_start, carry.margin, elapsed, cpu, commits)
        arrays["frame_step"] = np.array([k for k, _ in frames], dtype=np.int64)
        arrays["frame_time"] = np.array([f.time for _, f in frames])
        arrays.update(_diagnostic_arrays(diagnostics))
        _write(path, arrays)
    except OSError:
        if first:
            frames_path(path).unlink(missing_ok=True)
        raise


def load_checkpoint(path, fingerprint):
    """The saved run ({state, frames, diagnostics, carry, elapsed, cpu}) if `path` holds a checkpoint of
    this fingerprint (its frames file cut to the frames it lists), None if it holds none (its frames
    file, if any, removed: the run starts over); a CheckpointError for another run's or an unreadable
    file, or frames missing."""
    saved = _read(path, fingerprint, lambda arrays: _restore(arrays, path, fingerprint))
    if saved is None and path is not None:
        frames_path(path).unlink(missing_ok=True)
    return saved


def frames_path(path) -> Path:
    """Where the frames of the collapse checkpointed at `path` lie."""
    return Path(f"{path}.frames")


def remove_checkpoint(path) -> None:
    """Remove a checkpoint and its frames file (either may be absent)."""
    Path(path).unlink(missing_ok=True)
    frames_path(path).unlink(missing_ok=True)


def save_packing_checkpoint(path, fingerprint, state, warm, margin, loop: dict, elapsed, cpu=float("nan"),
                            diagnostics=(), commits=()):
    """A packing in the middle of a cloud: `state` (all spheres placed), the forces by pair `warm`
    (WarmStart in the numbering of `state`, or None) and the detection `margin` (None: the base
    one) that the next step starts from, and `loop`: the filling loop's arrays and numbers
    (name -> array, bool, int, float or str); `elapsed` and `cpu`: the wall and CPU seconds spent so
    far; `diagnostics`: the StepDiagnostics of the steps so far; `commits`: as :func:`save_checkpoint`'s."""
    arrays = _common_arrays(fingerprint, state, warm, margin, elapsed, cpu, commits)
    arrays.update(_diagnostic_arrays(diagnostics))
    for name, value in loop.items():
        arrays[f"loop_{name}"] = np.asarray(value)
    _write(path, arrays)


def load_packing_checkpoint(path, fingerprint):
    """The saved packing ({state, warm, margin, loop, diagnostics, elapsed, cpu}) if `path` holds a
    packing checkpoint of this fingerprint; None (with a warning) otherwise. loop's values come back
    as numpy arrays (0-d for numbers and text); diagnostics is empty for a checkpoint written before
    packings kept them."""
    def restore(arrays):
        state, warm, margin = _common_of(arrays)
        loop = {name[len("loop_"):]: value for name, value in arrays.items() if name.startswith("loop_")}
        diagnostics = _diagnostics_of(arrays) if "diagnostic_step" in arrays else []
        return {"state": state, "warm": warm, "margin": margin, "loop": loop, "diagnostics": diagnostics,
                **_spent(arrays)}
    return _read(path, fingerprint, restore)


def checkpoint_summary(path) -> dict:
    """What a checkpoint says of its run, without restoring it or checking whose it is: {stage:
    "collapse" or "packing", spheres, step (the last one done), time (simulated), kinetic_energy
    (translational, of the last step), seconds_per_step (wall, mean over the last 10 steps), elapsed
    and cpu (wall and CPU seconds so far)}; NaN where an older checkpoint lacks the step record.
    Reads only the small arrays."""
    with np.load(path, allow_pickle=False) as archive:
        names = set(archive.files)
        stage = "collapse" if "frame_step" in names else "packing"
        spheres = int(archive["radius"].shape[0])
        time = float(archive["state_time"])
        spent = _spent(archive)
        if "diagnostic_step" in names and archive["diagnostic_step"].size:
            step = int(archive["diagnostic_step"][-1])
            energy = float(archive["diagnostic_kinetic_energy"][-1])
            per_step = float(np.mean(archive["diagnostic_wall_time"][-10:]))
        else:
            step, energy, per_step = -1, float("nan"), float("nan")
    return {"stage": stage, "spheres": spheres, "step": step, "time": time, "kinetic_energy": energy,
            "seconds_per_step": per_step, **spent}


def _write(path, arrays: dict) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez(handle, **arrays)


def check_checkpoint_path(path) -> None:
    """CheckpointError unless `path` is absent or a regular file holding a colsim checkpoint (of any
    run; :func:`load_checkpoint` checks whose), and its frames path absent or a colsim frames file:
    what is there may be read and, at the end, removed."""
    _check_frames_path(frames_path(path))
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        return
    if path.is_symlink() or not path.is_file():
        raise CheckpointError(f"checkpoint {path} exists and is not a regular file: colsim will not replace it;"
                              " give --checkpoint a new path")
    try:
        with np.load(path, allow_pickle=False) as archive:
            if "fingerprint" not in archive.files:
                raise ValueError("no fingerprint")
    except Exception:
        raise CheckpointError(f"{path} exists and is not a colsim checkpoint: colsim will not read or replace it;"
                              " give --checkpoint a new path, or remove the file") from None


#: far more arrays than a checkpoint holds (about 40)
MAX_CHECKPOINT_ARRAYS = 1000


def _check_archive(path) -> None:
    """ValueError unless the .npz at `path` holds at most MAX_CHECKPOINT_ARRAYS arrays, each stored
    uncompressed (as np.savez stores them) and declaring no more bytes than it holds: a small file
    declaring gigabytes is refused before numpy allocates them."""
    import zipfile

    with zipfile.ZipFile(path) as archive:
        members = archive.infolist()
        if len(members) > MAX_CHECKPOINT_ARRAYS:
            raise ValueError(f"it holds {len(members):,} arrays, more than a checkpoint may ({MAX_CHECKPOINT_ARRAYS:,})")
        for member in members:
            if member.compress_type != zipfile.ZIP_STORED or member.compress_size != member.file_size:
                raise ValueError(f"its array {member.filename} is compressed; colsim stores checkpoints uncompressed")
            with archive.open(member) as stream:
                version = np.lib.format.read_magic(stream)
                read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                               else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read_header(stream)
            declared = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
            if declared > member.file_size:
                raise ValueError(f"its array {member.filename} declares {declared:,} bytes but holds"
                                 f" {member.file_size:,}")


def _read(path, fingerprint, restore):
    """restore(arrays) of the checkpoint at `path` if it is this run's (fingerprint), None if there is
    none; a CheckpointError for anything else at the path, or for a saved state that fails the
    input checks."""
    if path is None:
        return None
    check_checkpoint_path(path)
    if not Path(path).exists():
        return None
    try:
        _check_archive(path)
        with np.load(path, allow_pickle=False) as archive:
            found = str(archive["fingerprint"])
            arrays = dict(archive) if found == fingerprint else None
    except Exception as error:
        raise CheckpointError(f"checkpoint {path} cannot be read ({error}); remove it to start the run over") from None
    if arrays is None:
        raise CheckpointError(f"checkpoint {path} belongs to another run (other inputs or settings): colsim will"
                              " not replace it; remove it to start this run over, or give --checkpoint another path")
    try:
        restored = restore(arrays)
    except Exception as error:   # a checkpoint written by an older colsim, or edited
        raise CheckpointError(f"checkpoint {path} is not one this colsim can resume ({type(error).__name__}:"
                              f" {error}); remove it to start the run over") from None
    import xarray
    try:
        check_geometry(restored["state"], xarray.Dataset(), path)
        _check_warm_start(restored, path)
    except InputError as error:
        raise CheckpointError(f"{error}; remove the checkpoint to start the run over") from None
    restored["commits"] = [str(c) for c in arrays.get("commits", np.array(["unknown (before commits were kept)"]))]
    earlier = [c for c in restored["commits"] if c != source_commit()]
    if earlier:
        log.warning("resuming %s, written by other code (%s); the output lists every commit", path, "; ".join(earlier))
    return restored


def _check_warm_start(restored, path) -> None:
    """InputError unless the carried contact forces name spheres of the saved state (a wall, or a
    fixed sphere of the pour) and are finite, as an input file's are (checks.check_contacts)."""
    warm = restored["carry"].warm_start if "carry" in restored else restored["warm"]
    if warm is None:
        return
    n = restored["state"].n
    try:
        checks.check_contacts(warm.i, warm.j, warm.family, warm.force, warm.rolling, n=n, fixed=n)
    except checks.FileProblem as problem:
        raise InputError(f"checkpoint {path}: its warm start: {problem}") from None


def _restore(arrays, path, fingerprint) -> dict:
    """The run saved by :func:`save_checkpoint` from its arrays (its frames from the frames file
    beside `path`, or, written before there was one, from the arrays)."""
    state, warm, margin = _common_of(arrays)
    if "frame_position" in arrays:
        frames = [(int(k), ParticleState(*(arrays[f"frame_{name}"][n] for name in STATE_FIELDS), state.radius,
                                         state.density, float(arrays["frame_time"][n])))
                  for n, k in enumerate(arrays["frame_step"])]
    else:
        frames = _read_frames(path, fingerprint, state, arrays["frame_step"], arrays["frame_time"])
    return {"state": state, "frames": frames, "diagnostics": _diagnostics_of(arrays), "carry": Carry(warm, margin),
            **_spent(arrays)}


def _diagnostic_arrays(diagnostics) -> dict:
    """diagnostic_<field>: one array a field of StepDiagnostics, over the steps."""
    return {f"diagnostic_{name}": np.array([getattr(d, name) for d in diagnostics],
                                           dtype=str if name in TEXT_DIAGNOSTICS else None)
            for name in StepDiagnostics.__dataclass_fields__}


def _diagnostics_of(arrays) -> list:
    """The StepDiagnostics saved by :func:`_diagnostic_arrays` (a field added since: its default)."""
    fields = [name for name in StepDiagnostics.__dataclass_fields__ if f"diagnostic_{name}" in arrays]
    columns = {name: arrays[f"diagnostic_{name}"].tolist() for name in fields}
    return [StepDiagnostics(**{name: columns[name][k] for name in fields}) for k in range(len(columns["step"]))]


def segment_commits(earlier) -> list[str]:
    """The commits of a run's segments: the earlier ones, then this process's unless it is the last."""
    commits = [str(c) for c in earlier]
    return commits if commits and commits[-1] == source_commit() else commits + [source_commit()]


def _common_arrays(fingerprint, state, warm, margin, elapsed, cpu, commits=()) -> dict:
    """What both checkpoints hold: the fingerprint, the state, the forces by pair (if any) and the
    detection margin (NaN for None) the next step starts from, the wall and CPU seconds spent, and the
    commits of the segments (the earlier ones given, this one's added)."""
    arrays = {"fingerprint": np.array(fingerprint), "elapsed": np.array(elapsed), "cpu": np.array(cpu),
              "commits": np.array(segment_commits(commits), dtype=str),
              "radius": state.radius,
              "density": np.array(state.density), "state_time": np.array(state.time),
              "margin": np.array(np.nan if margin is None else margin)}
    for name in STATE_FIELDS:
        arrays[f"state_{name}"] = getattr(state, name)
    if warm is not None:
        for name in WARM_FIELDS:
            arrays[f"warm_{name}"] = getattr(warm, name)
    return arrays


def _spent(arrays) -> dict:
    """{elapsed, cpu}: the wall and CPU seconds a checkpoint's run had taken (cpu NaN for a checkpoint
    written before it was saved)."""
    return {"elapsed": float(arrays["elapsed"]), "cpu": float(arrays["cpu"]) if "cpu" in arrays else float("nan")}


def _common_of(arrays) -> tuple:
    """(state, warm start or None, margin or None) from :func:`_common_arrays`' arrays."""
    state = ParticleState(*(arrays[f"state_{name}"] for name in STATE_FIELDS), arrays["radius"],
                          float(arrays["density"]), float(arrays["state_time"]))
    warm = WarmStart(*(arrays[f"warm_{name}"] for name in WARM_FIELDS)) if "warm_i" in arrays else None
    margin = float(arrays["margin"])
    return state, warm, None if np.isnan(margin) else margin


# -- a collapse's frames file -----------------------------------------------------------------

def _frames_header(fingerprint: str, n: int) -> bytes:
    header = FRAMES_MAGIC + f"{fingerprint}\n{n}\n".encode()
    if len(header) > FRAMES_HEADER:
        raise ValueError("a fingerprint too long for the frames file's header")
    return header.ljust(FRAMES_HEADER, b" ")


def _record_size(n: int) -> int:
    """Bytes of one frame's record (step, time, then 9 n numbers)."""
    return 8 * (2 + 9 * n)


def _check_frames_path(path: Path) -> None:
    """CheckpointError unless `path` is absent or a regular file that starts as a colsim frames file
    (or as the start of one: a run killed while it wrote the header)."""
    if not path.exists() and not path.is_symlink():
        return
    if path.is_symlink() or not path.is_file():
        raise CheckpointError(f"{path} exists and is not a regular file: colsim will not replace it;"
                              " give --checkpoint a new path")
    with open(path, "rb") as handle:
        if not FRAMES_MAGIC.startswith(handle.read(len(FRAMES_MAGIC))):
            raise CheckpointError(f"{path} exists and is not a colsim frames file: colsim will not read or replace"
                                  " it; give --checkpoint a new path, or remove the file")


def _frames_held(path: Path, header: bytes, n: int) -> int:
    """How many whole records the frames file at `path` holds after `header` (0: absent, or another
    run's)."""
    if not path.is_file():
        return 0
    with open(path, "rb") as handle:
        if handle.read(FRAMES_HEADER) != header:
            return 0
    return (path.stat().st_size - FRAMES_HEADER) // _record_size(n)


def _append_frames(path, fingerprint: str, n: int, frames) -> None:
    """Make the frames file of the checkpoint at `path` hold `frames` ([(step, state)]): the records
    it holds for this run stay (they are frames[:held], written by earlier checkpoints of this run, cut
    to those the last checkpoint listed when it was loaded), the rest are appended."""
    target, header = frames_path(path), _frames_header(fingerprint, n)
    held = _frames_held(target, header, n)
    if held > len(frames):
        held = 0
    with open(target, "r+b" if held else "wb") as handle:
        if not held:
            handle.write(header)
        handle.seek(FRAMES_HEADER + held * _record_size(n))
        handle.truncate()
        for step, frame in frames[held:]:
            handle.write(np.array([step, frame.time], dtype="<f8").tobytes())
            for name in STATE_FIELDS:
                handle.write(np.ascontiguousarray(getattr(frame, name), dtype="<f8").tobytes())


def _read_frames(path, fingerprint: str, state: ParticleState, steps, times) -> list:
    """The frames (steps, times) of the checkpoint at `path` from its frames file, which is cut to them."""
    target, n = frames_path(path), state.n
    header, size = _frames_header(fingerprint, n), _record_size(n)
    count = len(steps)
    if not target.is_file():
        raise ValueError(f"its frames file {target} is missing")
    with open(target, "rb") as handle:
        if handle.read(FRAMES_HEADER) != header:
            raise ValueError(f"its frames file {target} is another run's")
    if (target.stat().st_size - FRAMES_HEADER) // size < count:
        raise ValueError(f"its frames file {target} is short of its {count} frames")
    records = np.fromfile(target, dtype="<f8", count=count * size // 8, offset=FRAMES_HEADER).reshape(count, -1)
    if not (np.array_equal(records[:, 0], steps) and np.array_equal(records[:, 1], times)):
        raise ValueError(f"its frames file {target} holds other frames than it lists")
    with open(target, "r+b") as handle:
        handle.truncate(FRAMES_HEADER + count * size)
    motion = records[:, 2:].reshape(count, 3, n, 3)   # each frame's three (n, 3) arrays are contiguous views
    return [(int(step), ParticleState(*motion[k], state.radius, state.density, float(time)))
            for k, (step, time) in enumerate(zip(steps, times))]
