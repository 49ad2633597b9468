"""The rows ingest writes stay what they were (issue 67, item 3): the read stage was made faster
(the fast path's heading and status, the vessel tallies, the slow reports' spill), and what comes
out of it must not move. The first day of the shipped MarineCadastre zip, made hostile where a
real export is (a quoted name with a comma, a blank heading, a damaged status, a number the fast
path leaves to the usual way, a row cut short, the header repeated mid-file), is ingested, and a
digest of every output table is compared with the one the code before that change wrote."""

from __future__ import annotations

import hashlib
import json
import zipfile
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from aisdati.preprocess.pipeline import ingest
from aisdati.preprocess.settings import IngestSettings
from tests.helpers.ingest import DATA

SETTINGS = IngestSettings(min_points=5, clusters="direction", rows_per_bucket=30_000)
"""Four vessel partitions of the day; routes left out (they are not the read stage's)."""

PINNED = {
    "points.parquet": "3897a20ef023cb88a0c6c4d14be84a9ad9f8f05e052f344d666074e6373783a2",
    "reports.parquet": "92f7d47db6786549c3f7d08588993cd721a596a7e56d42e06dc4e27db8d572ed",
    "tracks.parquet": "25686f0074ded33e62af1e7dee8b4c0409c82836bae16cfbe7ce723f80580ffc",
    "vessels.parquet": "38ec3a6e144a94089bac7b81796444aef2f7fdaf8f4cc438ebbd5b9491a49b94",
}
"""sha256 of each output's rows (`digest`), as the code before issue 67's item 3 wrote them."""
PINNED_COUNTS = "a58f7beee1d78e205a2b878bd6852beb36b51f7ca2ff9e36b533d701750da539"
"""sha256 of ingest_report.json's counts (rows read, each reason, kept points and reports)."""


def hostile_day(data: Path, out: Path) -> Path:
    """The shipped day with odd rows put in among its plain ones, every 211th row changed."""
    with zipfile.ZipFile(data / "AIS_2022_01_03_head.zip") as zf:
        header, *rows = zf.read("AIS_2022_01_03.csv").decode().splitlines()
    odd = [
        lambda f: [*f[:7], f'"{f[7]}, JR"', *f[8:]],  # a comma in a quoted name
        lambda f: [*f[:6], "", *f[7:]],  # a blank heading
        lambda f: [*f[:11], "x", *f[12:]],  # a damaged status
        lambda f: [*f[:4], f"{float(f[4]):.2e}" if f[4] else "", *f[5:]],  # SOG as 1.23e+01
        lambda f: f[:9],  # cut short: malformed
    ]
    lines = [header]
    for k, row in enumerate(rows):
        if k % 211 == 0:
            row = ",".join(odd[(k // 211) % len(odd)](row.split(",")))
        lines.append(row)
        if k == len(rows) // 2:
            lines.append(header)
    path = out / "hostile_day.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def digest(table: pd.DataFrame) -> str:
    """sha256 of a table's rows in their order (values, nulls and column names)."""
    h = hashlib.sha256(",".join(table.columns).encode())
    h.update(pd.util.hash_pandas_object(table, index=False).to_numpy().tobytes())
    return h.hexdigest()


def counts_digest(report: dict) -> str:
    keys = ("rows_read", "rejected", "kept_points", "reports_kept", "tracks")
    return hashlib.sha256(
        json.dumps({k: report[k] for k in keys}, sort_keys=True).encode()
    ).hexdigest()


@pytest.fixture(scope="module")
def hostile(tmp_path_factory) -> tuple[Path, dict]:
    """The hostile day ingested once (`SETTINGS`)."""
    folder = tmp_path_factory.mktemp("pinned")
    source = hostile_day(DATA, folder)
    result = ingest([source], folder / "out", SETTINGS, None, "none")
    return folder / "out", result.as_dict()


def test_the_hostile_day_is_read_as_before(hostile):
    out, report = hostile
    assert report["rejected"]["malformed_row"] > 0 and report["rejected"]["header_line"] == 1
    assert counts_digest(report) == PINNED_COUNTS
    got = {name: digest(pq.read_table(out / name).to_pandas()) for name in PINNED}
    assert got == PINNED


if __name__ == "__main__":  # the digests of the code as it is (to pin an intended change)
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        day = hostile_day(DATA, Path(tmp))
        report = ingest([day], Path(tmp) / "out", SETTINGS, None, "none").as_dict()
        print("PINNED_COUNTS =", repr(counts_digest(report)))
        for name in PINNED:
            print(repr(name), repr(digest(pq.read_table(Path(tmp) / "out" / name).to_pandas())))
