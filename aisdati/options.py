"""Checks shared by every command, before any work: numeric options, output folders, signals and
the sweep of temporary files that killed runs left behind.

* `check_options` validates CLI numbers in one place: every float option must be finite (typer
  reads `nan` and `inf` as floats, and NaN compares false with every bound, so a NaN threshold
  would silently switch its filter off) and inside the range `OPTION_RANGES` gives it.
* `prepare_output_dir` is the one "make this folder ready for our outputs" of every command: the
  path is a folder (or can be made one), we can write into it, none of the files we are about to
  write is a folder, and stale temporary files of earlier, killed runs are swept out of it.
* `handle_termination` makes SIGTERM behave like Ctrl-C (the same clean-up runs), and ignores
  a second SIGTERM while that clean-up is under way; `raise_if_interrupted`, called before every
  output is committed, raises again a signal whose exception a C callback swallowed.

Temporary names (all in the folder that will hold the output, so that the final rename is atomic):
`.ingest-<pid>-<random>/` (ingest's spill folder, holding a `.lock` that its run keeps locked),
`.<output>.<pid>.tmp` (ingest's staged outputs) and `.<output>.<random>.tmp` (`atomic_write_bytes`
of train and detect). A temporary is stale when its run cannot still be writing it: its lock is
free, its process is gone, or (names without a process id) it is older than this process.
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import re
import shutil
import signal
import sys
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aisdati.errors import UserError

try:  # POSIX; elsewhere the sweep falls back on process ids and ages
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

STARTED = time.time()
"""When this process imported aisdati (close enough to its start for the sweep's age test)."""


# ------------------------------------------------------------------------------ lists of names
def parse_names(text: str | Iterable[str], known: Iterable[str], what: str) -> tuple[str, ...]:
    """'a,b' (or several such strings) -> ('a', 'b'), lower-cased, without repeats; none, or a
    name not in `known`, is a one-line `UserError` that lists the choices (`what`: "method",
    "detector", ...)."""
    known = list(known)
    items = [text] if isinstance(text, str) else list(text)
    names = tuple(
        dict.fromkeys(n.strip().lower() for t in items for n in t.split(",") if n.strip())
    )
    if not names:
        raise UserError(f"no {what} given; choose from {', '.join(known)}")
    for name in names:
        if name not in known:
            raise UserError(f"unknown {what} {name!r}; choose from {', '.join(known)}")
    return names


# ------------------------------------------------------------------------------ numeric options
@dataclass(frozen=True)
class Range:
    """Allowed values of a numeric option: finite, and within (or at) the bounds given."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def accepts(self, value: float) -> bool:
        if not math.isfinite(value):
            return False
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return False
        return not (
            self.high is not None and (value >= self.high if self.high_open else value > self.high)
        )

    def describe(self) -> str:
        if self.low is not None and self.high is not None:
            left, right = "(" if self.low_open else "[", ")" if self.high_open else "]"
            return f"in {left}{_fmt(self.low)}, {_fmt(self.high)}{right}"
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {_fmt(self.low)}"
        if self.high is not None:
            return f"{'<' if self.high_open else '<='} {_fmt(self.high)}"
        return ""


def _fmt(x: float) -> str:
    if isinstance(x, float) and math.isnan(x):
        return "nan"
    if float(x).is_integer() and abs(x) < 1e15:
        return str(int(x))
    return f"{x:g}"


SEED_MAX = 2**32 - 1
OPTION_RANGES: dict[str, Range] = {
    # ingest
    "--min-sog": Range(high=102.2, high_open=True),  # negative: keep every SOG, even 0
    "--max-speed": Range(low=0.0, low_open=True),
    "--stop-gap": Range(low=0.0, low_open=True, high=365 * 86400.0),  # seconds
    "--dwell-time": Range(low=0.0, high=365 * 86400.0),  # seconds; 0: no dwell stops
    "--dwell-radius": Range(low=0.0, low_open=True, high=100_000.0),  # metres
    "--route-eps-km": Range(low=0.0, low_open=True, high=20_037.5),
    # detect
    "--threshold": Range(low=0.0, low_open=True, high=1.0),
    "--top-percent": Range(low=0.0, low_open=True, high=100.0),
    "--near-km": Range(low=0.0, low_open=True, high=20_037.5),  # half the Earth's circumference
    "--lane-course-km": Range(low=0.0, high=1000.0),
    "--contamination": Range(low=0.0, low_open=True, high=1.0, high_open=True),
    # evaluate
    "--train-fraction": Range(low=0.1, high=0.9),
    # integers that reach a random generator (numpy refuses negative seeds, torch huge ones)
    "--seed": Range(low=0, high=SEED_MAX),
}
"""Every numeric option that needs more than its type, with its allowed range. Floats are always
checked for finiteness, ranged or not."""


def check_option(name: str, value: float | None) -> None:
    """Raise a one-line `UserError` unless `value` is finite and in the range of `name` (None, an
    option left unset, passes)."""
    if value is None:
        return
    allowed = OPTION_RANGES.get(name, Range())
    if not allowed.accepts(float(value)):
        kind = "an integer" if isinstance(value, int) else "a finite number"
        rule = allowed.describe()
        raise UserError(f"{name} must be {kind}{' ' + rule if rule else ''}, got {_fmt(value)}")


def check_options(values: dict[str, float | None]) -> None:
    """`check_option` for each (option name, value): call it first thing in a command."""
    for name, value in values.items():
        check_option(name, value)


# ------------------------------------------------------------------------------ output folders
def prepare_output_dir(path: Path, option: str = "--out", outputs: Iterable[str] = ()) -> Path:
    """Make `path` a folder we can write our outputs into, or raise a one-line `UserError`: the
    path is a file, lies under a file, cannot be created or written, or one of `outputs` (the
    names about to be written there) is a folder. Then sweep our stale temporaries out of it."""
    path = Path(path)

    def refuse(reason: str) -> UserError:
        return UserError(f"cannot write to output folder {path} ({option}): {reason}")

    if path.exists() and not path.is_dir():
        raise refuse("it is a file, not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise refuse(f"cannot create it, {_reason(exc)}") from None
    probe = path / f".aisdati-write-test.{os.getpid()}.tmp"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise refuse(_reason(exc)) from None
    for name in outputs:
        if (path / name).is_dir():
            raise refuse(
                f"{name} there is a folder, where the output file goes; "
                "move it away or choose another folder"
            )
    sweep_stale_temporaries(path)
    return path


def _reason(exc: OSError) -> str:
    if exc.errno in (errno.EACCES, errno.EPERM):
        return "no write permission"
    if exc.errno == errno.ENOTDIR:
        return "a part of the path is a file"
    if exc.errno == errno.EROFS:
        return "read-only file system"
    return exc.strerror or type(exc).__name__


# --------------------------------------------------------------------------- stale temporaries
INGEST_DIR = re.compile(r"^\.ingest-(?:(\d+)-)?[A-Za-z0-9_]+$")
"""Ingest's spill folder: `.ingest-<pid>-<random>` (older versions: `.ingest-<random>`)."""
TMP_FILE = re.compile(
    r"^\.(?:aisdati-write-test|.+\.(?:parquet|json|jsonl|geojson|pt|ckpt|npz|png|html|csv))"
    r"\.(?:(\d+)|[A-Za-z0-9_]{8})\.tmp$"
)
"""Our temporary files: `.<output>.<pid>.tmp` (staged) and `.<output>.<8 random>.tmp` (mkstemp)."""
LOCK_NAME = ".lock"


@contextlib.contextmanager
def hold_lock(folder: Path) -> Iterator[None]:
    """Keep `<folder>/.lock` locked while the block runs: the sweep of another process then knows
    the folder is in use. The lock dies with the process, even on SIGKILL."""
    if fcntl is None:  # pragma: no cover
        yield
        return
    fd = os.open(folder / LOCK_NAME, os.O_CREAT | os.O_RDWR, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _locked(lock: Path) -> bool | None:
    """Whether another open file holds `lock` (None: no lock file, or no way to tell)."""
    if fcntl is None or not lock.is_file():
        return None
    try:
        fd = os.open(lock, os.O_RDWR)
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
    match = INGEST_DIR.match(path.name) if path.is_dir() else TMP_FILE.match(path.name)
    if match is None:
        return False
    if path.is_dir():
        locked = _locked(path / LOCK_NAME)
        if locked is not None:
            return not locked
    pid = match.group(1)
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


# ----------------------------------------------------------------------------------- signals
class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C's KeyboardInterrupt so that the same clean-up runs."""


_PENDING: list[type[KeyboardInterrupt]] = []
"""Signals received in `handle_termination`'s block, in case their exception was swallowed."""


def raise_if_interrupted() -> None:
    """Raise a signal's exception again before an output is committed. Python raises a signal's
    exception in whatever code runs when it arrives; inside a C callback (numba compiling a
    function calls back into Python) it is printed as "Exception ignored" and lost, and the run
    would go on to write complete-looking outputs and exit 0 after a Ctrl-C."""
    if _PENDING:
        raise _PENDING[0]()


@contextlib.contextmanager
def handle_termination() -> Iterator[None]:
    """While the block runs, SIGTERM raises `Terminated` (once: a second SIGTERM during the
    clean-up is ignored) and both it and Ctrl-C are remembered for `raise_if_interrupted`.
    Outside the main thread this does nothing (signals cannot be set); a SIGINT that the
    process inherited as ignored (nohup) stays ignored."""

    def on_term(signum: int, frame: Any) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        _PENDING.append(Terminated)
        raise Terminated()

    def on_int(signum: int, frame: Any) -> None:
        _PENDING.append(KeyboardInterrupt)
        raise KeyboardInterrupt()

    try:
        previous = signal.signal(signal.SIGTERM, on_term)
    except ValueError:  # not the main thread
        yield
        return
    before = signal.getsignal(signal.SIGINT)
    if before is signal.default_int_handler:
        signal.signal(signal.SIGINT, on_int)
    hook = sys.unraisablehook

    def quiet(unraisable: Any) -> None:  # a swallowed signal: remembered, so no traceback
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            hook(unraisable)

    sys.unraisablehook = quiet
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, before)
        sys.unraisablehook = hook
        _PENDING.clear()
