"""Which torch device DATI's networks run on (`--device auto|cpu|cuda`).

Only DATI's networks move (training, validation rollouts and scoring rollouts); the
environments, DTW, the baselines (BC, DDPG-TI, nearest) and every random draw stay on the CPU.
The draws come from the members' CPU generators whatever the device, so a model trained on a
GPU starts from the same weights and sees the same batches and noise as on the CPU: its results
differ only by the float rounding of the GPU's kernels. The name is resolved once, in the
command, to a plain string ("cpu", "cuda:0") that travels to Dask workers with the settings.
"""

from __future__ import annotations

import re

from aisdati.errors import UserError


def resolve_device(choice: str) -> str:
    """'auto' -> 'cuda:0' when torch sees a CUDA device, else 'cpu'; 'cpu'; 'cuda' or 'cuda:N'
    checked against the devices torch sees. Anything else, or a GPU that is not there, is a
    one-line `UserError`."""
    import torch

    name = choice.strip().lower()
    if name == "auto":
        return "cuda:0" if torch.cuda.is_available() else "cpu"
    if name == "cpu":
        return "cpu"
    match = re.fullmatch(r"cuda(?::(\d+))?", name)
    if match is None:
        raise UserError(f"--device must be auto, cpu, cuda or cuda:N, got {choice!r}")
    if not torch.cuda.is_available():
        build = f"torch {torch.__version__}" + ("" if torch.version.cuda else ", a CPU build")
        raise UserError(f"--device {name}: torch sees no CUDA device ({build}); use --device cpu")
    index = int(match.group(1) or 0)
    if index >= torch.cuda.device_count():
        raise UserError(
            f"--device {name}: torch sees {torch.cuda.device_count()} CUDA device(s), "
            f"numbered from 0"
        )
    return f"cuda:{index}"
