"""Ctrl-C and SIGTERM (`aisdati.interrupts`): real signals sent to a real `aisdati ingest`
leave nothing behind (issue 13, item 15), and a Ctrl-C that C code swallows still stops the
outputs."""

from __future__ import annotations

import os
import signal

import pytest

from tests.helpers.processes import start_big_ingest, temporaries


# --------------------------------------------------------------------------------- item 15
@pytest.mark.parametrize(
    "sig, rc, word", [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")]
)
def test_sigterm_and_sigint_during_ingest_leave_nothing(tmp_path, sig, rc, word):
    out = tmp_path / "out"
    proc = start_big_ingest(out)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == rc, err
    assert word in err and "Traceback" not in err
    assert temporaries(out) == []
    assert not (out / "points.parquet").exists()


def _interrupt_inside_a_c_callback() -> None:
    """Ctrl-C arriving while C code calls back into Python (as numba's JIT does): the
    KeyboardInterrupt is raised in the callback, printed as "Exception ignored" and lost."""
    import ctypes

    libc = ctypes.CDLL(None)
    compare = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)

    def cmp(a, b):
        os.kill(os.getpid(), signal.SIGINT)
        return 0

    values = (ctypes.c_int * 2)(2, 1)
    libc.qsort(values, 2, ctypes.sizeof(ctypes.c_int), compare(cmp))


def test_a_ctrl_c_swallowed_by_a_c_callback_still_stops_the_outputs(tmp_path, capfd):
    from aisdati.interrupts import handle_termination, raise_if_interrupted
    from aisdati.outdir import atomic_write_bytes

    # a test run started in the background may inherit an ignored SIGINT: give it the default
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with handle_termination():
            _interrupt_inside_a_c_callback()  # returns: the exception did not propagate
            with pytest.raises(KeyboardInterrupt):
                atomic_write_bytes(tmp_path / "model.json", b"{}")
            with pytest.raises(KeyboardInterrupt):
                raise_if_interrupted()
        assert list(tmp_path.iterdir()) == []  # nothing committed, no temporary left
        assert "Traceback" not in capfd.readouterr().err  # not printed: it was remembered
        raise_if_interrupted()  # outside the block the memory is cleared
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, inherited)
