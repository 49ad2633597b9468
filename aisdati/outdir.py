"""Output folders: make one ready for a command's outputs, land the outputs as one set, write
each file atomically, and sweep out what killed runs left behind.

* `prepare_output_dir` is the one "make this folder ready for our outputs" of every command: the
  path is a folder (or can be made one), we can write into it, none of the files we are about to
  write is a folder, and stale temporaries of earlier, killed runs are swept out of it.
* `staged_outputs` is how ingest, detect and evaluate write their --out (see below).
* `atomic_write_bytes` writes one file under a temporary name and renames it: a reader never
  sees a half-written file, and a Ctrl-C before the rename commits nothing.

How a command's outputs stay one consistent set
-----------------------------------------------
A command writes its whole output set into a staging folder inside --out,
`<out>/.staging-<pid>-<random>/`, and moves it in only once every file of it is complete
(`OutputSet.commit`), in this order: the earlier run's report (`ingest_report.json`,
`report.json`, `evaluation.json`) is removed; what the earlier run wrote and this one does not
(only our own output names, never anything else in the folder) is removed; the new files are
renamed into place, the report last. Nothing is written while this happens (renames only, in one
file system), and SIGINT and SIGTERM are held until it is done. So a Ctrl-C, a SIGTERM or a
failed write leaves either the earlier run's set untouched (it came before the commit: the
staging folder is deleted) or the new set whole (it came during the commit: the run exits 130 or
143 after it). The report is the set's seal: a folder never holds a report beside another run's
files, so even a SIGKILL or a power cut in the middle of the renames leaves a folder without a
report (an unfinished run), not a mixed one. A staging folder left by a killed run is swept like
the other stale temporaries.

An output may be a folder of part files (`datasets`: ingest's points.parquet, a Parquet dataset
that tasks on several workers write side by side). It moves in with one rename, and the earlier
run's folder of that name (or file, from versions that wrote one) is first set aside into the
staging folder with one rename, and deleted with it: a reader never sees the parts of two runs
in one folder, nor half of one run's parts. A folder of that name holding anything but part
files (`is_dataset`) is not ours: the command refuses to start.

Why a staging folder rather than a manifest written last that every reader checks: the readers
of these folders are mostly not ours (GIS tools, notebooks, `pyarrow`, a browser opening
map.html), and none of them would check a manifest. With the staging folder every reader sees
complete sets without knowing about it; the report-last rule gives a careful reader the
manifest's guarantee as well. `evaluate` writes its working data (`data/`, `models/`) in place,
because its model cards record where their training data lies: it removes the earlier run's
set, report first, before it rewrites them (`OutputSet.retire_earlier`), and stages its results.

One writer per folder: the command holds a lock on --out itself (`hold_lock`, released when the
process ends, even on SIGKILL) from its start to its commit; a second writer gets one line and
exit code 2.

Temporary names (all inside the folder that will hold the output, so that renames are atomic)
carry the writer's process id: `.ingest-<pid>-<random>/` (ingest's spill folder),
`.staging-<pid>-<random>/` (a command's staged outputs) and `.<output>.<pid>-<random>.tmp`
(`temporary_path`, every single file written). A temporary is stale when its run cannot still
be writing it: nobody holds its lock and its process is gone, or (names of older versions
without a process id) it is older than this process.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import shutil
import signal
import tempfile
import time
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aisdati.errors import UserError
from aisdati.interrupts import raise_if_interrupted

if TYPE_CHECKING:
    import pyarrow as pa

try:  # POSIX; elsewhere the sweep falls back on process ids and ages
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

STARTED = time.time()
"""When this process imported aisdati (close enough to its start for the sweep's age test)."""


# ------------------------------------------------------------------------------ output folders
URL_LIKE = re.compile(r"^([A-Za-z][A-Za-z0-9+.\-]+):/")
"""A URL given for an output folder (`memory://r`, which a path option reads as `memory:/r`):
refused, rather than written as a local folder named `memory:`."""


def same_folder(a: str | Path, b: str | Path) -> bool:
    """Whether two folder options name the same folder (whatever the spelling or links)."""
    return Path(a).expanduser().resolve() == Path(b).expanduser().resolve()


@contextlib.contextmanager
def removed_if_left_empty(path: Path) -> Iterator[None]:
    """For the time of the block: a folder that did not exist before it and that the block
    leaves empty on failure (an unreachable cluster, a refused input) is removed again, so that
    a failed command leaves nothing behind that looks like its output."""
    existed = Path(path).exists()
    try:
        yield
    except BaseException:
        folder = Path(path)
        if not existed and folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
        raise


def prepare_output_dir(
    path: Path, option: str = "--out", outputs: Iterable[str] = (), datasets: Iterable[str] = ()
) -> Path:
    """Make `path` a folder we can write our outputs into, or raise a one-line `UserError`: the
    path is a file, lies under a file, cannot be created or written, or one of `outputs` (the
    names about to be written there) is a folder (for one of `datasets`, the outputs that are
    folders of part files: a folder that holds other files). Then sweep our stale temporaries
    out of it."""
    path = Path(path)
    if scheme := URL_LIKE.match(str(path)):
        raise UserError(
            f"{option} {scheme[1]}://...: a URL, where this command writes a local folder "
            "(only `aisdati train --out` copies its models to a URL)"
        )
    if path.exists() and not path.is_dir():
        raise _refuse(path, option, "it is a file, not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _refuse(path, option, f"cannot create it, {_reason(exc)}") from None
    probe = path / f".aisdati-write-test.{os.getpid()}.tmp"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise _refuse(path, option, _reason(exc)) from None
    datasets = set(datasets)
    for name in outputs:
        if name in datasets and (path / name).is_dir() and not is_dataset(path / name):
            raise _refuse(
                path,
                option,
                f"{name} there is a folder holding other files than the part-NNNNN.parquet of "
                "an earlier run; move it away or choose another folder",
            )
        if name not in datasets and (path / name).is_dir():
            raise _refuse(
                path,
                option,
                f"{name} there is a folder, where the output file goes; "
                "move it away or choose another folder",
            )
    sweep_stale_temporaries(path)
    return path


DATASET_PART = re.compile(r"^part-\d+\.parquet$")
"""The name of one part file of a dataset folder (`part-00000.parquet`, ...)."""


def is_dataset(path: Path) -> bool:
    """Whether the folder `path` holds nothing but part files: a dataset an earlier run wrote,
    which a new run may replace."""
    try:
        return all(DATASET_PART.match(p.name) and p.is_file() for p in path.iterdir())
    except OSError:
        return False


def _refuse(path: Path, option: str, reason: str) -> UserError:
    return UserError(f"cannot write to output folder {path} ({option}): {reason}")


def _reason(exc: OSError) -> str:
    if exc.errno in (errno.EACCES, errno.EPERM):
        return "no write permission"
    if exc.errno == errno.ENOTDIR:
        return "a part of the path is a file"
    if exc.errno == errno.EROFS:
        return "read-only file system"
    return exc.strerror or type(exc).__name__


# ------------------------------------------------------------------------- staged output sets
class OutputSet:
    """A command's outputs: written under `folder` (the staging folder, by their paths relative
    to --out) and moved into `out` as one set by `commit` (see the module docstring)."""

    def __init__(
        self,
        out: Path,
        folder: Path,
        owned: Sequence[str],
        report: str,
        datasets: Sequence[str] = (),
    ) -> None:
        self.out = out
        self.folder = folder
        self.owned = tuple(owned)
        """Glob patterns, relative to `out`, of every file a run of the command may write."""
        self.report = report
        """The name of the set's report, its seal: moved in last, removed first."""
        self.datasets = tuple(datasets)
        """Names among `owned` of outputs that are folders of part files, moved as one."""

    def final(self, staged: Path) -> Path:
        """Where the staged file `staged` lands in --out."""
        return self.out / Path(staged).relative_to(self.folder)

    def retire_earlier(self) -> None:
        """Remove the earlier run's set now, report first, for a command about to rewrite in
        place what that set describes (evaluate's data and models)."""
        with _signals_held():
            for path in sorted(self._earlier(), key=lambda p: p.name != self.report):
                self._remove(path)

    def commit(self) -> None:
        """Move every staged file into --out as one set, the earlier run's leftovers removed
        (only our own names: `owned`); a failed rename is one `UserError`."""
        raise_if_interrupted()
        staged = self._staged()
        new = set(staged)
        seals = [self.out / rel for rel in staged if rel.name == self.report]
        seals.append(self.out / self.report)
        leftovers = [p for p in self._earlier() if p.relative_to(self.out) not in new]
        # reports last, the deepest first and the top one at the very end
        staged.sort(key=lambda rel: (rel.name == self.report, -len(rel.parts)))
        with _signals_held():
            for path in seals + leftovers:
                self._remove(path)
            for rel in staged:
                target = self.out / rel
                try:
                    self._unlink_linked_folders(rel)
                    target.parent.mkdir(parents=True, exist_ok=True)
                    if rel.as_posix() in self.datasets and (target.exists() or target.is_symlink()):
                        self._set_aside(target)  # a rename cannot replace a folder, or by one
                    os.replace(self.folder / rel, target)
                except OSError as exc:
                    raise UserError(f"cannot write {target}: {_reason(exc)}") from None

    def _staged(self) -> list[Path]:
        """What to move in, relative to the staging folder: each dataset folder as one, and
        every other file."""
        folders = [Path(d) for d in self.datasets if _is_folder(self.folder / d)]
        files = [p.relative_to(self.folder) for p in self.folder.rglob("*") if p.is_file()]
        return folders + [f for f in files if not any(d in f.parents for d in folders)]

    def _earlier(self) -> list[Path]:
        """The files (and dataset folders) of ours in --out now: what earlier runs left."""
        found = {p for pattern in self.owned for p in self.out.glob(pattern)}
        found = {p for p in found if not self._linked_folder(p.relative_to(self.out))}
        files = {p for p in found if p.is_file() or p.is_symlink()}
        return sorted(files | {self.out / d for d in self.datasets if _is_folder(self.out / d)})

    def _linked_folder(self, rel: Path) -> Path | None:
        """The first folder on the way to `rel` under --out that is a link, if any: our outputs
        never go through one (a link `evidence/` would have the figures written, and old ones
        deleted, wherever it points)."""
        for parent in reversed(rel.parents[:-1]):
            if (self.out / parent).is_symlink():
                return self.out / parent
        return None

    def _unlink_linked_folders(self, rel: Path) -> None:
        """Replace a link on the way to `rel` by the folder of ours it stands for: the link
        itself is removed, never what it points to."""
        link = self._linked_folder(rel)
        while link is not None:
            link.unlink()
            link = self._linked_folder(rel)

    def _remove(self, path: Path) -> None:
        """Delete one output of ours (a dataset folder: set aside whole), and its folder under
        --out if that is left empty (evidence/)."""
        if _is_folder(path):
            self._set_aside(path)
        else:
            path.unlink(missing_ok=True)
        parent = path.parent
        if parent != self.out:
            with contextlib.suppress(OSError):  # not empty: it holds the user's files or new ones
                parent.rmdir()

    def _set_aside(self, path: Path) -> None:
        """Move an earlier output out of --out with one rename, into the staging folder, which
        is deleted with everything in it once the command ends."""
        aside = self.folder / ".replaced"
        aside.mkdir(exist_ok=True)
        os.rename(path, aside / f"{sum(1 for _ in aside.iterdir())}-{path.name}")


def _is_folder(path: Path) -> bool:
    return path.is_dir() and not path.is_symlink()


@contextlib.contextmanager
def staged_outputs(
    out: Path,
    owned: Sequence[str],
    report: str,
    option: str = "--out",
    datasets: Sequence[str] = (),
) -> Iterator[OutputSet]:
    """Prepare `out` (`prepare_output_dir`), lock it for this run (a second writer: one-line
    `UserError`), and yield the `OutputSet` to write into (`datasets`: the outputs that are
    folders of part files); whatever ends the block before its `commit` (an error, Ctrl-C,
    SIGTERM) leaves --out as it was."""
    out = Path(out)
    prepare_output_dir(out, option, [n for n in owned if not _is_glob(n)], datasets)
    for sub in sorted({Path(n).parts[0] for n in owned if len(Path(n).parts) > 1}):
        if (out / sub).exists() and not (out / sub).is_dir():
            raise _refuse(out, option, f"{sub} there is a file, where the output folder goes")
        sweep_stale_temporaries(out / sub)
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(hold_lock(out, wait=False))
        except BlockingIOError:
            busy = "another aisdati run is writing to it; wait for it to end or choose another one"
            raise _refuse(out, option, busy) from None
        folder = Path(tempfile.mkdtemp(dir=out, prefix=f".staging-{os.getpid()}-"))
        stack.callback(shutil.rmtree, folder, ignore_errors=True)
        yield OutputSet(out, folder, owned, report, datasets)


def _is_glob(name: str) -> bool:
    return any(c in name for c in "*?[")


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM wait until the block is over, then arrive as usual: a commit is never
    cut in two. (Outside the main thread signals cannot be set, nor do they arrive there.)"""
    held: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        held.append(signum)

    try:
        previous = {s: signal.signal(s, hold) for s in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:
        yield
        return
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        for s in held:
            signal.raise_signal(s)


# --------------------------------------------------------------------------- stale temporaries
WORK_DIR = re.compile(r"^\.(?:ingest|staging)-(?:(?P<pid>\d+)-)?[A-Za-z0-9_]+$")
"""Ingest's spill folder `.ingest-<pid>-<random>` and a command's `.staging-<pid>-<random>`
(older versions: `.ingest-<random>`)."""
TMP_FILE = re.compile(
    r"^\.(?:aisdati-write-test|.+\.(?:parquet|json|jsonl|geojson|pt|ckpt|npz|png|html|csv))"
    r"\.(?:(?P<pid>\d+)(?:-[A-Za-z0-9_]+)?|[A-Za-z0-9_]{8})\.tmp$"
)
"""Our temporary files: `.<output>.<pid>-<random>.tmp` (`temporary_path`); older versions:
`.<output>.<pid>.tmp` and `.<output>.<8 random>.tmp`."""
OLD_FIGURE_TMP = re.compile(r"^\..+\.tmp\.(?:png|html)$")
"""The figures' and pages' temporaries of older versions (`.map.tmp.png`), without a pid."""


@contextlib.contextmanager
def hold_lock(folder: Path, wait: bool = True) -> Iterator[None]:
    """Keep `folder` itself locked while the block runs: the sweep of another process then knows
    it is in use, and (`wait=False`: `BlockingIOError` at once when another holds it) a second
    writer knows it is taken. The lock leaves no file behind and dies with the process, even on
    SIGKILL."""
    if fcntl is None:  # pragma: no cover
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
        yield
    finally:
        os.close(fd)


def _locked(folder: Path) -> bool | None:
    """Whether another open file holds `folder`'s lock (None: no way to tell)."""
    if fcntl is None:
        return None
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)  # closing releases our own probe lock
    return False


def _process_start(pid: int) -> float | None:
    """Start time (epoch seconds) of a live process, from /proc on Linux; None elsewhere."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        boot = next(
            float(line.split()[1])
            for line in Path("/proc/stat").read_text().splitlines()
            if line.startswith("btime ")
        )
        ticks = float(stat.rsplit(")", 1)[1].split()[19])
        return boot + ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration):
        return None


def _writer_alive(pid: int, mtime: float) -> bool:
    """Whether process `pid` may still be writing a temporary last modified at `mtime`: it is
    alive, and (where we can tell) it started before the file was written (no reused pid)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # alive, another user's
    started = _process_start(pid)
    return started is None or started <= mtime + 1.0


def is_stale(path: Path) -> bool:
    """Whether `path`, one of our temporary names, belongs to a run that is over."""
    try:
        mtime = path.lstat().st_mtime
    except OSError:
        return False
    if path.is_dir():
        match = WORK_DIR.match(path.name)
        if match is None or _locked(path):
            return False
    else:
        match = TMP_FILE.match(path.name) or OLD_FIGURE_TMP.match(path.name)
        if match is None:
            return False
    pid = match.groupdict().get("pid")
    if pid is not None:
        return not _writer_alive(int(pid), mtime)
    return mtime < STARTED


def sweep_stale_temporaries(folder: Path) -> list[Path]:
    """Remove the stale temporaries (see the module docstring) directly inside `folder`; returns
    what was removed. Anything that is not one of our names is left alone."""
    removed: list[Path] = []
    try:
        entries = list(folder.iterdir())
    except OSError:
        return removed
    for entry in entries:
        if not entry.name.startswith(".") or not is_stale(entry):
            continue
        try:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
        except OSError:
            continue  # someone else's, or gone already: not ours to insist on
        removed.append(entry)
    return removed


# ------------------------------------------------------------------------------ atomic writes
def temporary_path(path: Path) -> Path:
    """The name to write `path` under until it is whole: `.<name>.<pid>-<random>.tmp` beside
    it, the one temporary name of every file aisdati writes (the sweep knows it by the pid)."""
    return path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp")


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write to a temporary file beside `path`, then rename: never a half-written file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_path(path)
    try:
        with open(tmp, "xb") as fh:
            fh.write(data)
        raise_if_interrupted()
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def parquet_bytes(table: pa.Table) -> bytes:
    """`table` as the bytes of a parquet file (pyarrow's default compression), for
    `atomic_write_bytes`."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return sink.getvalue().to_pybytes()
