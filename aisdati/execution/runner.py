"""One way to run a list of independent tasks, whatever runs them.

Every command that has parallel work (ingest's partitions, one model per group of routes,
chunks of tracks to score) cuts it into tasks by a rule that depends on the data only, never on
the number of workers, and hands them to a `Runner`: `InProcess` runs them one after the other
in this process (the default; `InThreads` on threads, for a stage whose work releases the GIL),
`DaskRunner` as tasks
of a dask.distributed cluster, local processes started here (`--workers N`) or an existing
cluster (`--workers tcp://HOST:PORT`). The same tasks with the same inputs give the same
outputs, so the results do not depend on where they ran.

A task that dies with its worker (killed, out of memory) is run again on another one, up to
`RETRIES` times on a local cluster (an existing cluster keeps its own
`distributed.scheduler.allowed-failures`); a task that raises raises here, as in-process, and
is not run again: the same inputs would raise the same error.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from aisdati.errors import UserError

T = TypeVar("T")
R = TypeVar("R")

RETRIES = 3
"""Times a task lost with its worker is started again elsewhere (local clusters)."""
WORKER_WAIT_S = 60
"""How long a command waits for the first worker of an existing cluster that has none."""
CONNECT_TIMEOUT_S = 10
"""How long `--workers ADDRESS` waits for the scheduler to answer before giving up, in one
line."""
WORKER_MEMORY = "auto"
"""Each local worker's memory limit: the machine's memory shared equally (Dask's `auto`)."""
CLUSTER_LOG_LEVEL = logging.CRITICAL
"""What a local cluster's processes print: nothing short of critical. What matters reaches the
command as a task's exception (a lost worker's tasks are retried, then fail in one line); the
rest is Dask's own logging, which on Ctrl-C printed a worker's heartbeat traceback when the
scheduler closed first."""


@dataclass(frozen=True)
class Execution:
    """Where a command's tasks run: `workers` local processes, or the cluster behind
    `scheduler` (an address such as tcp://10.0.0.5:8786). One worker and no scheduler: in this
    process."""

    workers: int = 1
    scheduler: str | None = None

    def __post_init__(self) -> None:
        if self.workers < 1:
            raise UserError(f"--workers must be at least 1, got {self.workers}")
        if self.scheduler is not None and self.workers != 1:
            raise UserError("an existing cluster brings its own workers: a count or an address")

    @classmethod
    def parse(cls, text: str | int) -> Execution:
        """`--workers`: a number of local processes, or the address of an existing Dask
        scheduler (tcp://HOST:PORT, or any SCHEME://...)."""
        text = str(text).strip()
        if "://" in text:
            return cls(scheduler=text)
        try:
            return cls(workers=int(text))
        except ValueError:
            raise UserError(
                f"--workers {text!r}: expected a number of processes or a scheduler address "
                "(tcp://HOST:PORT)"
            ) from None

    @property
    def distributed(self) -> bool:
        return self.scheduler is not None or self.workers > 1

    def describe(self) -> str:
        if self.scheduler is not None:
            return f"Dask cluster at {self.scheduler}"
        if self.workers > 1:
            return f"{self.workers} local Dask workers"
        return "in-process"


class Runner(Protocol):
    """Runs `fn` on each item and returns the results in the items' order; `on_done(i)` is
    called as task i ends (in any order), for progress bars. `costs`, when given, are the
    items' expected work: a cluster starts the costliest first (longest processing time
    first), so that the last task to end is a short one and the workers finish together."""

    workers: int

    def map(
        self,
        fn: Callable[[T], R],
        items: Sequence[T],
        on_done: Callable[[int], None] | None = None,
        costs: Sequence[float] | None = None,
    ) -> list[R]: ...


class InProcess:
    """The tasks one after the other, here."""

    workers = 1
    threads = 1

    def map(
        self,
        fn: Callable[[T], R],
        items: Sequence[T],
        on_done: Callable[[int], None] | None = None,
        costs: Sequence[float] | None = None,
    ) -> list[R]:
        del costs  # one after the other, or taken in order by the threads: costs change nothing
        with contextlib.ExitStack() as stack:
            if self.threads > 1:
                ran = stack.enter_context(ThreadPoolExecutor(self.threads)).map(fn, items)
            else:
                ran = map(fn, items)
            results = []
            for i, result in enumerate(ran):
                results.append(result)
                if on_done is not None:
                    on_done(i)
        return results


class InThreads(InProcess):
    """The tasks in this process on `threads` threads, the results in the items' order: for
    tasks whose work mostly releases the GIL (numpy, Arrow, compiled kernels) and whose memory
    allows that many at once. `on_done` is called in the items' order."""

    def __init__(self, threads: int) -> None:
        self.threads = threads


class DaskRunner:
    """The tasks on a dask.distributed cluster, through `client`."""

    def __init__(self, client: Any):
        self.client = client
        self.workers = max(1, len(client.scheduler_info().get("workers", {})))

    def map(
        self,
        fn: Callable[[T], R],
        items: Sequence[T],
        on_done: Callable[[int], None] | None = None,
        costs: Sequence[float] | None = None,
    ) -> list[R]:
        from distributed import as_completed

        if not items:
            return []
        # costliest first, in submission and in priority (a task may start before the next
        # one is submitted); pure=False: unique keys, never shared by equal items
        order = sorted(range(len(items)), key=lambda i: -costs[i]) if costs else range(len(items))
        by_item = {
            i: self.client.submit(fn, items[i], pure=False, priority=len(items) - r)
            for r, i in enumerate(order)
        }
        futures = [by_item[i] for i in range(len(items))]
        index = {f.key: i for i, f in enumerate(futures)}
        try:
            for future in as_completed(futures):
                if future.status == "error":
                    future.result()  # raises the task's own exception here
                if on_done is not None:
                    on_done(index[future.key])
            return self.client.gather(futures)
        except BaseException:
            self.client.cancel(futures)  # the others' work is of no use any more
            raise


@contextlib.contextmanager
def open_runner(execution: Execution) -> Iterator[Runner]:
    """The runner of `execution`, for the time of the block: a local cluster started and shut
    down with it, or a client of the existing one. A scheduler that does not answer within
    `CONNECT_TIMEOUT_S` is a one-line `UserError`."""
    if not execution.distributed:
        yield InProcess()
        return
    from distributed import Client, LocalCluster  # here: in-process runs never load Dask

    with contextlib.ExitStack() as stack:
        if execution.scheduler is not None:
            client = stack.enter_context(_connect(Client, execution.scheduler))
        else:
            import dask

            stack.enter_context(
                dask.config.set({"distributed.scheduler.allowed-failures": RETRIES})
            )
            cluster = stack.enter_context(
                LocalCluster(
                    n_workers=execution.workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=":0",  # any free port, never the 8787 of another cluster
                    memory_limit=WORKER_MEMORY,
                    silence_logs=CLUSTER_LOG_LEVEL,
                )
            )
            client = stack.enter_context(Client(cluster))
        yield DaskRunner(client)


@contextlib.contextmanager
def _connect(client_class: Any, address: str) -> Iterator[Any]:
    try:
        client = client_class(address, timeout=f"{CONNECT_TIMEOUT_S}s")
    except (OSError, TimeoutError, ValueError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise UserError(f"cannot reach the Dask scheduler at {address}: {reason}") from None
    with client:
        _wait_for_a_worker(client, address)
        yield client


def _wait_for_a_worker(client: Any, address: str) -> None:
    """A scheduler without workers would hold every task forever: say that it waits, and give up
    after `WORKER_WAIT_S` in one line."""
    if client.scheduler_info().get("workers"):
        return
    print(f"waiting up to {WORKER_WAIT_S} s for a worker of the Dask cluster at {address}",
          file=sys.stderr)  # fmt: skip
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except TimeoutError:
        raise UserError(
            f"the Dask cluster at {address} has no worker (waited {WORKER_WAIT_S} s): start one, "
            f"e.g. `dask worker {address}`"
        ) from None
