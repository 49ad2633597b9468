"""Where the work runs: in this process, or as tasks on a Dask cluster (`--workers`,
`--scheduler`; `aisdati.execution.runner`), and on which torch device DATI's networks run
(`--device`; `aisdati.execution.device`)."""

from aisdati.execution.device import resolve_device
from aisdati.execution.runner import Execution, InProcess, InThreads, Runner, open_runner

__all__ = ["Execution", "InProcess", "InThreads", "Runner", "open_runner", "resolve_device"]
