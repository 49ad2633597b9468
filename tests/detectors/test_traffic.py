"""The training tracks a `nearest` model keeps (`aisdati.detectors.traffic`), damaged the ways
a disk, a transfer or a hand edit damages them (issue 27, items 8 and 10): one line naming the
file and what is wrong, never a crash of the process."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest

from tests.helpers.cli import one_line_error
from tests.helpers.models import (
    copy_of,
    detect_with,
    edit_npz,
    not_an_archive,
    object_array,
    rewrite_npz,
    truncate,
)


def _set(arrays, key, value):
    arrays[key] = value


# ------------------------------------------------------------------------------ item 8
@pytest.mark.parametrize("bad", [np.nan, np.inf], ids=["nan", "inf"])
def test_nearest_positions_of_nan_or_inf_are_refused_not_a_segfault(ny_models, tmp_path, bad):
    """NaN costs made the DTW back-track leave its matrix and write past its path (rc 139):
    run in a process of its own, so that a crash fails this test instead of the session."""
    models = copy_of(ny_models, tmp_path, digests=False)
    rewrite_npz(models / "down-nearest.npz", lambda z: z["positions"].fill(bad))
    proc = subprocess.run(
        [sys.executable, "-m", "aisdati.cli", "detect", "--data", str(ny_models["proc"]),
         "--models", str(models), "--out", str(tmp_path / "r"), "--method", "nearest",
         "--score", "rollout", "--near-km", "20"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert re.search(
        r"cannot load .*down-nearest\.npz: 'positions' holds non-finite values", proc.stderr
    ), proc.stderr


# ----------------------------------------------------------------------------- item 10
NEAREST_DAMAGE = [
    ("truncated", truncate, "not a readable .npz"),
    ("not-a-zip", not_an_archive, "not a readable .npz"),
    ("descending-offsets", edit_npz(lambda z: _set(z, "offsets", z["offsets"][::-1].copy())),
     "the offsets must rise from 0 to"),
    ("offsets-past-the-end", edit_npz(lambda z: z["offsets"].__setitem__(-1, 10**9)),
     "the offsets must rise from 0 to"),
    ("uint-offsets-descending", edit_npz(lambda z: _set(
        z, "offsets", np.array([0, 90, 40, z["offsets"][-1]], np.uint64))),
     "the offsets must rise from 0 to"),
    ("float-offsets", edit_npz(lambda z: _set(z, "offsets", z["offsets"] + 0.5)),
     "'offsets' must hold integers, got float64"),
    ("positions-of-3", edit_npz(lambda z: _set(z, "positions", np.ones((len(z["positions"]), 3)))),
     r"'positions' must have shape \[n, 2\], got \[\d+, 3\]"),
    ("missing-mmsi", edit_npz(lambda z: z.pop("mmsi")), "it has no 'mmsi' array"),
    ("object-array", object_array("mmsi"), "'mmsi' holds Python objects"),
    ("fewer-tracks", edit_npz(lambda z: (_set(z, "offsets", z["offsets"][:-1]),
                                         _set(z, "mmsi", z["mmsi"][:-1]))),
     "it holds 2 tracks and 2 vessels, the card 3"),
    ("fewer-positions", edit_npz(lambda z: _set(z, "positions", z["positions"][:-1])),
     r"it holds \d+ positions, the card says \d+"),
    ("not-degrees", edit_npz(lambda z: z["positions"].__setitem__(0, [500.0, 40.0])),
     r"positions must be \(lon, lat\) in degrees"),
]  # fmt: skip


@pytest.mark.parametrize("damage, needle", [d[1:] for d in NEAREST_DAMAGE],
                         ids=[d[0] for d in NEAREST_DAMAGE])  # fmt: skip
def test_a_damaged_nearest_npz_is_one_line(ny_models, tmp_path, damage, needle):
    models = copy_of(ny_models, tmp_path, digests=False)
    damage(models / "down-nearest.npz")
    result = detect_with(ny_models, models, tmp_path / "r", "nearest", "--score", "rollout")
    one_line_error(result, r"cannot load .*down-nearest\.npz: " + needle)
