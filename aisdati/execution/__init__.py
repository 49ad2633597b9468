"""Where the work runs: in this process, or as tasks on a Dask cluster (`--workers`,
`--scheduler`); see `aisdati.execution.runner`."""

from aisdati.execution.runner import Execution, InProcess, Runner, open_runner

__all__ = ["Execution", "InProcess", "Runner", "open_runner"]
