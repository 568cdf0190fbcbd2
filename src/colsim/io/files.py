"""Writing files so that nothing half-written is taken for a result: a temporary name beside the
target, renamed when complete (:func:`atomic_path`, :func:`write_all`), the checks that an output can
be written, and :class:`InputError`, the one-line error of a bad input or output."""
from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from pathlib import Path


class InputError(ValueError):
    """An input file that is missing, unreadable or of the wrong kind."""


#: what mkstemp adds to a temporary's prefix and suffix: 8 random characters
RANDOM_PART = 8
#: the longest file name where the file system does not say (POSIX's NAME_MAX on Linux and macOS)
NAME_MAX = 255


def _name_max(folder) -> int:
    """The longest file name `folder`'s file system takes."""
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        return NAME_MAX


def temporary_prefix(path, suffix: str) -> str:
    """The prefix of a hidden temporary beside `path` ending in `suffix`: '.' and as much of
    `path`'s name as the file system's name limit leaves room for (a legal 243-byte output name
    made a temporary name too long), then '.'."""
    path = Path(path)
    room = _name_max(path.parent if path.parent.exists() else ".") - len(suffix) - RANDOM_PART - 2
    return f".{path.name[:room]}."


def remove_stale_temporaries(path) -> list[Path]:
    """Remove the temporaries of `path` (`.NAME.XXXXXXXX.part`, :func:`atomic_path`'s) that a killed
    run left beside it; a stage calls it on its own outputs as it starts. Returns those removed."""
    path = Path(path)
    if not path.parent.is_dir():
        return []
    prefix = temporary_prefix(path, ".part")
    stale = [found for found in path.parent.iterdir()
             if found.name.startswith(prefix) and found.name.endswith(".part")
             and len(found.name) == len(prefix) + RANDOM_PART + len(".part") and found.is_file()
             and not found.is_symlink()]
    for found in stale:
        found.unlink()
    return stale


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside `path`; rename it to `path` only if the block succeeds. An
    OSError that names no file (a full disk, as netCDF reports it) is raised naming `path`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=temporary_prefix(path, ".part"), suffix=".part", dir=path.parent)
    os.close(fd)
    try:
        try:
            yield Path(tmp)
        except OSError as error:
            if error.filename is None:
                raise OSError(error.errno, error.strerror or str(error), str(path)) from error
            raise
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_all(writers: dict) -> None:
    """All or nothing: writers maps each output path to a callable that writes it to the path it is
    given. Each writes to a temporary name beside its path (:func:`atomic_path`); the files are
    renamed into place, in the dict's order, only once every one of them is complete, so a failure
    leaves none of them new."""
    with contextlib.ExitStack() as stack:   # exits last-entered first: enter in reverse order
        temporaries = {path: stack.enter_context(atomic_path(path)) for path in reversed(list(writers))}
        for path, write in writers.items():
            write(temporaries[path])


def check_writable(path, directory: bool = False) -> None:
    """InputError (one line) unless a file `path` (or files in the directory `path`) can be written:
    the nearest existing folder on the way must take a new file. Leaves nothing behind."""
    path = Path(path)
    if path.is_dir() != directory and path.exists():
        raise InputError(f"cannot write {path}: it is {'not ' if directory else ''}a directory")
    folder = path if directory else path.parent
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"cannot write {path}: {folder} is not a directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=temporary_prefix(folder / path.name, ".probe"), suffix=".probe",
                                     dir=folder)
    except OSError as error:
        raise InputError(f"cannot write {path}: {folder} takes no new files ({error.strerror})") from None
    os.close(fd)
    os.remove(probe)


def read_regular_text(path, limit: int, what: str) -> str:
    """The text of `path`, a regular file of at most `limit` bytes; InputError (one line) naming `what`
    and the path otherwise: missing, a FIFO (reading it would block), a device (/dev/zero never ends),
    a folder, or too large. Its kind and size are checked before it is opened."""
    path = Path(path)
    try:
        found = os.stat(path)
    except OSError as error:
        raise InputError(f"{what} {path} cannot be read ({error.strerror})") from None
    if not stat.S_ISREG(found.st_mode):
        raise InputError(f"{what} {path} is not a regular file (a FIFO, a device or a folder): colsim reads"
                         " a settings file only from a regular file")
    if found.st_size > limit:
        raise InputError(f"{what} {path} has {found.st_size:,} bytes, more than a {what} may ({limit:,})")
    with open(path, "rb") as stream:
        data = stream.read(limit + 1)
    if len(data) > limit:   # grew since its size was read
        raise InputError(f"{what} {path} has more than {limit:,} bytes, more than a {what} may")
    try:
        return data.decode()
    except UnicodeDecodeError:
        raise InputError(f"{what} {path} is not UTF-8 text") from None
