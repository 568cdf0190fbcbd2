"""A benchmark's figures as a file: what ran, where, on which code, and the rows of its tables.

    import record                                     # with benchmarks/ on sys.path
    table = record.table(["spheres", "s/step"])       # prints the Markdown header
    table.row(1000, f"{seconds:.2f}", data={"seconds": seconds})   # prints the row, keeps it

    record.run("step", main)                          # a script's __main__: run main, then write

A benchmark prints its tables as before; :func:`table` also keeps every row (the cells as printed,
and optionally the unrounded figures as `data`) in the current :class:`Record`. When the benchmark
ends, the record is written as JSON to ``results/benchmarks/<name>-<UTC timestamp>.json`` (the
folder: ``$COLSIM_BENCHMARK_RESULTS`` when set, or ``python -m benchmarks --results DIR``), written
to a temporary name and renamed, so a file there is always whole. A run that printed no table (a
benchmark's own child process, an error before the first row) writes nothing.

The file holds: ``benchmark``, ``arguments``, ``date`` (UTC, ISO 8601), ``machine`` (CPU model,
cores, usable cores, memory, load average, platform), ``versions`` (python, numpy, scipy, numba,
clarabel, xarray, and where colsim was imported from), ``git`` (commit, dirty, branch), ``notes``
(anything else a benchmark records, e.g. how its packing was made), ``wall_s``, ``complete``
(false when the benchmark stopped on an error, whose rows so far are kept) and ``tables``
(each: title, columns, rows as {column: printed cell}, and data when given).
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import sys
import tempfile
from importlib import metadata
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parent.parent
RESULTS_ENV = "COLSIM_BENCHMARK_RESULTS"
CACHE_ENV = "COLSIM_BENCHMARK_CACHE"
PACKAGES = ("numpy", "scipy", "numba", "clarabel", "xarray")


def results_dir() -> Path:
    """Where records go: $COLSIM_BENCHMARK_RESULTS, else results/benchmarks/ in the repository."""
    return Path(os.environ.get(RESULTS_ENV) or REPOSITORY / "results" / "benchmarks")


def cache_dir() -> Path:
    """Where benchmarks keep what they build to measure on (packings, columns): $COLSIM_BENCHMARK_CACHE,
    else benchmarks/.cache/ (git-ignored)."""
    return Path(os.environ.get(CACHE_ENV) or Path(__file__).resolve().parent / ".cache")


def machine() -> dict:
    """CPU model (/proc/cpuinfo, else platform), core counts, memory (GiB), load average."""
    model = None
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    model = model or platform.processor() or platform.machine()
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError, AttributeError):
        memory = None
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    from colsim.engine.threads import allowed_cpus   # the CPUs this process may use, as colsim counts them
    return {"cpu": model, "cores": os.cpu_count(), "usable_cores": allowed_cpus(),
            "memory_gib": None if memory is None else round(memory, 1), "load_average": load,
            "platform": platform.platform(), "hostname": platform.node()}


def versions() -> dict:
    """Python's and the key packages' versions (None: not installed), and colsim's source folder."""
    found = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    colsim = sys.modules.get("colsim")
    found["colsim_source"] = str(Path(colsim.__file__).parent) if colsim is not None else None
    return found


def git_state(folder: Path = REPOSITORY) -> dict:
    """The commit checked out in `folder`, whether its tracked files differ from it, the branch."""
    from colsim.io.git import git_state as state

    return state(folder)


def write_json(path: Path, content: dict) -> Path:
    """Write `content` to `path` atomically: a temporary file in the same folder, then a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w") as out:
            json.dump(content, out, indent=1, default=_plain)
            out.write("\n")
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


def _plain(value):
    """numpy scalars and arrays, paths, sets: as JSON can hold them."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, (set, frozenset, tuple)):
        return list(value)
    return str(value)


class Table:
    """One printed Markdown table whose rows are kept in a record."""

    def __init__(self, columns, title: str = "", echo: bool = True, file=None):
        self.columns, self.title, self.echo, self.file = list(columns), title, echo, file
        self.rows: list[dict] = []
        self.data: list[dict] = []
        if echo:
            self._print("| " + " | ".join(self.columns) + " |")
            self._print("|" + "---|" * len(self.columns))

    def _print(self, line: str) -> None:
        print(line, file=self.file or sys.stdout, flush=True)

    def row(self, *cells, data: dict | None = None) -> None:
        """Print (when echoing) and keep one row; `data`: its unrounded figures, kept beside it."""
        if len(cells) != len(self.columns):
            raise ValueError(f"{len(cells)} cells for {len(self.columns)} columns {self.columns}")
        cells = [str(c) for c in cells]
        self.rows.append(dict(zip(self.columns, cells)))
        if data is not None:
            self.data.append(data)
        if self.echo:
            self._print("| " + " | ".join(cells) + " |")

    def as_dict(self) -> dict:
        out = {"title": self.title, "columns": self.columns, "rows": self.rows}
        if self.data:
            out["data"] = self.data
        return out


class Record:
    """What one benchmark run measured, with where and on what it ran."""

    def __init__(self, name: str, arguments=()):
        self.name, self.arguments = name, [str(a) for a in arguments]
        self.started = _dt.datetime.now(_dt.timezone.utc)
        self.tables: list[Table] = []
        self.notes: dict = {}
        self.complete = True

    def table(self, columns, title: str = "", echo: bool = True) -> Table:
        table = Table(columns, title, echo)
        self.tables.append(table)
        return table

    def note(self, key: str, value) -> None:
        """Keep something beside the tables (appended to a list when noted again)."""
        if key in self.notes:
            previous = self.notes[key]
            self.notes[key] = (previous if isinstance(previous, list) else [previous]) + [value]
        else:
            self.notes[key] = value

    def as_dict(self) -> dict:
        ended = _dt.datetime.now(_dt.timezone.utc)
        return {"benchmark": self.name, "arguments": self.arguments,
                "date": self.started.isoformat(timespec="seconds"),
                "wall_s": round((ended - self.started).total_seconds(), 3), "complete": self.complete,
                "machine": machine(), "versions": versions(), "git": git_state(),
                "notes": self.notes, "tables": [t.as_dict() for t in self.tables]}

    def path(self, folder: Path | None = None) -> Path:
        """<folder>/<name>-<UTC start, YYYYmmddTHHMMSSZ>.json, with -2, -3... if that is taken."""
        folder = Path(folder) if folder is not None else results_dir()
        stem = f"{self.name}-{self.started.strftime('%Y%m%dT%H%M%SZ')}"
        path, k = folder / f"{stem}.json", 1
        while path.exists():
            k += 1
            path = folder / f"{stem}-{k}.json"
        return path

    def write(self, folder: Path | None = None) -> Path | None:
        """Write the record (None, nothing written, when no table was made)."""
        if not self.tables:
            return None
        return write_json(self.path(folder), self.as_dict())


_current: Record | None = None


def start(name: str, arguments=()) -> Record:
    """Make the record that :func:`table` and :func:`note` add to."""
    global _current
    _current = Record(name, arguments)
    return _current


def current() -> Record | None:
    return _current


def table(columns, title: str = "", echo: bool = True) -> Table:
    """A table in the current record (printed; kept only when a record was started)."""
    return _current.table(columns, title, echo) if _current is not None else Table(columns, title, echo)


def note(key: str, value) -> None:
    if _current is not None:
        _current.note(key, value)


def finish(folder: Path | None = None) -> Path | None:
    """Write the current record and forget it; say where on stderr."""
    global _current
    done, _current = _current, None
    path = done.write(folder) if done is not None else None
    if path is not None:
        print(f"record: {path}", file=sys.stderr, flush=True)
    return path


def run(name: str, main, argv=None, folder: Path | None = None):
    """Run a benchmark's main(argv) (argv None: sys.argv[1:]) in a record, then write the record."""
    argv = sys.argv[1:] if argv is None else list(argv)
    start(name, argv)
    try:
        result = main(argv)
    except BaseException as error:   # keep the rows measured so far, marked incomplete
        if _current is not None:
            _current.complete, _current.notes["error"] = False, repr(error)
        finish(folder)
        raise
    finish(folder)
    return result
