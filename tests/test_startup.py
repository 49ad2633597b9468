"""Startup is hardened (issue 27, item 16): a Ctrl-C while the CLI imports exits 130 with one
line, no traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

NY_HOUR = Path(__file__).parent / "data" / "NYHarbor_2020_06_30_first_hour.csv"


def _child(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)


def test_a_ctrl_c_while_the_cli_imports_exits_130_without_a_traceback():
    """Item 16: the console script (argv[0] 'aisdati') interrupted inside `import aisdati`
    (where Gymnasium loads), deterministically: the signal is sent from within the import."""
    code = (
        "import os, signal, sys\n"
        "sys.argv[0] = '/usr/local/bin/aisdati'\n"
        "import aisdati\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "import time; time.sleep(30)\n"
    )
    done = _child(code)
    assert done.returncode == 130, done.stderr
    assert done.stderr.strip() == "interrupted"


def test_once_the_cli_has_loaded_ctrl_c_is_pythons_again():
    """The guard ends when aisdati.cli has loaded (so click and each command's clean-up see the
    KeyboardInterrupt), and a library user's import never installs it."""
    code = (
        "import signal, sys\n"
        "sys.argv[0] = 'aisdati'\n"
        "import aisdati.cli\n"
        "assert signal.getsignal(signal.SIGINT) is signal.default_int_handler\n"
        "print('ok')\n"
    )
    assert _child(code).stdout.strip() == "ok"
    library = _child(
        "import signal, sys\nsys.argv[0] = 'analysis.py'\nimport aisdati\n"
        "print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)"
    )
    assert library.stdout.strip() == "True"
