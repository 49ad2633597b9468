"""The Danish Maritime Authority's CSV layout (aisdk-*.csv): columns by name, day-first times,
and real Kitimat reports written in that layout through `aisdati ingest`."""

from __future__ import annotations

import json
import zipfile

import pyarrow as pa
import pyarrow.parquet as pq

from aisdati.preprocess.convert import to_canonical
from aisdati.preprocess.inputs import Source
from aisdati.preprocess.layouts import DMA, MARINECADASTRE, layout_of, resolve_columns
from aisdati.preprocess.read import SourceReader
from aisdati.preprocess.report import CODE
from tests.helpers.kitimat_sample import (
    DMA_COLUMNS,
    DMA_SAMPLE,
    dma_layout,
    kitimat_rows,
    write_dma_sample,
)


def test_the_dma_header_is_recognised_and_its_columns_found():
    assert layout_of(DMA_COLUMNS) is DMA
    assert layout_of(["MMSI", "BaseDateTime", "LAT", "LON"]) is MARINECADASTRE
    assert resolve_columns(DMA_COLUMNS, "aisdk.csv") == {
        "time": "# Timestamp",
        "mmsi": "MMSI",
        "lat": "Latitude",
        "lon": "Longitude",
        "sog": "SOG",
        "cog": "COG",
        "status": "Navigational status",
        "heading": "Heading",
        "name": "Name",
        "ship_type": "Ship type",
        "length": "Length",
    }


def test_dma_times_are_day_first_utc_and_nothing_else():
    texts = ["01/12/2021 00:00:00", "13/01/2021 23:59:59", "2021-12-01T00:00:00"]
    texts += ["12/13/2021 00:00:00"]
    n = len(texts)
    batch = pa.record_batch(
        {
            "# Timestamp": pa.array(texts),
            "MMSI": pa.array(["219000001"] * n),
            "Latitude": pa.array(["55.7"] * n),
            "Longitude": pa.array(["12.6"] * n),
        }
    )
    columns = resolve_columns(batch.schema.names, "x")
    table, codes = to_canonical(batch, columns, 0, DMA.time_format)
    assert list(codes) == [0, 0, CODE["bad_time"], CODE["bad_time"]]  # month 13: not day first
    times = table.column("time").slice(0, 2).to_pylist()
    assert [t.isoformat() for t in times] == [
        "2021-12-01T00:00:00+00:00",
        "2021-01-13T23:59:59+00:00",
    ]


def test_the_fixture_is_what_its_script_writes(tmp_path):
    write_dma_sample(tmp_path / "sample.csv.gz")
    assert (tmp_path / "sample.csv.gz").read_bytes() == DMA_SAMPLE.read_bytes()


def test_a_zipped_dma_day_reads_like_the_csv(tmp_path):
    """DMA publishes days as aisdk-YYYY-MM-DD.zip holding one CSV."""
    archive = tmp_path / "aisdk-2018-07-01.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        zf.writestr("aisdk-2018-07-01.csv", dma_layout(kitimat_rows()).to_csv(index=False))
    zipped = SourceReader(Source(archive, "aisdk-2018-07-01.csv"))
    plain = SourceReader(Source(DMA_SAMPLE))
    assert zipped.time_format == plain.time_format == DMA.time_format
    read = [
        to_canonical(b, r.columns, 0, r.time_format)[0]
        for r in (zipped, plain)
        for b in r.batches()
    ]
    assert read[0].to_pandas().equals(read[1].to_pandas()) and read[0].num_rows == 3575


def test_kitimat_in_the_dma_layout_ingests_like_marinecadastre(cli, tmp_path):
    """The same 3,575 real reports, once in MarineCadastre's layout and once in the DMA's: the
    same points, tracks, reports and vessels, and the counts table printed."""
    csv = tmp_path / "kitimat.csv"
    kitimat_rows().to_csv(csv, index=False)
    args = ("--roi", "none", "--min-points", "20")
    result = cli("ingest", "--input", csv, "--out", tmp_path / "mc", *args, "--json")
    assert result.exit_code == 0, result.output
    baseline = json.loads(result.stdout)
    result = cli("ingest", "--input", DMA_SAMPLE, "--out", tmp_path / "dma", *args)
    assert result.exit_code == 0, result.output
    assert "aisdati ingest" in result.stdout and "3,575" in result.stdout
    report = json.loads((tmp_path / "dma" / "ingest_report.json").read_text())
    assert report["files"][0]["columns"]["time"] == "# Timestamp"
    for key in ("rows_read", "rejected", "kept_points", "tracks"):
        assert report[key] == baseline[key], key
    assert report["tracks"]["total"] == 32 and report["rejected"]["bad_time"] == 0
    for name in ("points.parquet", "tracks.parquet", "reports.parquet", "vessels.parquet"):
        got, want = (pq.read_table(tmp_path / out / name).to_pandas() for out in ("dma", "mc"))
        assert got.equals(want), name  # (pandas: a NaN heading equals NaN)
