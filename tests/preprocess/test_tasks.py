"""`aisdati ingest` on Dask workers (issue 29): a real `distributed.LocalCluster` of two worker
processes gives the outputs of one process (points and reports row for row, the same tracks,
vessels, routes, rejects and report); points.parquet is a Parquet dataset that DuckDB, pandas,
pyarrow and GeoPandas read; and a failed or interrupted run on workers leaves the folder as it
was."""

from __future__ import annotations

import gzip
import json
import logging
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import duckdb
import geopandas as gpd
import pandas as pd
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest
import shapely

import aisdati.preprocess.partition as partition
import aisdati.preprocess.pipeline as pipeline
from aisdati.execution.runner import Execution
from aisdati.outdir import staged_outputs
from aisdati.preprocess.settings import IngestSettings
from aisdati.tracks.store import load_tracks
from tests.helpers.cli import one_line_error

DATA = Path(__file__).parents[1] / "data"
ROOT = Path(__file__).resolve().parents[2]
KITIMAT = DATA / "AIS_2018_07-08_Kitimat.csv.gz"
NY_WEEK = DATA / "NYHarbor_2020_12_first_week_points.csv.gz"
KITIMAT_ARGS = ("--roi", "none", "--min-points", "100", "--keep-rejects")
NY_WEEK_ARGS = ("--roi", "none", "--min-points", "10", "--keep-rejects")
TIMINGS = ("seconds", "stage_seconds", "outputs")


@pytest.fixture(scope="module")
def cluster():
    """A local cluster of two worker processes, for the runs given its address (--workers)."""
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        silence_logs=logging.ERROR,
    ) as local:
        yield local.scheduler_address


def ingest(cli, out: Path, source: Path, *args) -> dict:
    result = cli("ingest", "--input", source, "--out", out, *args, "--json")
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


@pytest.fixture(scope="module")
def kitimat_runs(tmp_path_factory) -> tuple[Path, Path]:
    """Kitimat ingested in this process and with --workers 2 (a cluster of its own)."""
    from typer.testing import CliRunner

    from aisdati.cli import app

    base = tmp_path_factory.mktemp("kitimat")
    for name, extra in (("one", ()), ("two", ("--workers", "2"))):
        args = ["ingest", "--input", KITIMAT, "--out", base / name, *KITIMAT_ARGS, *extra]
        result = CliRunner().invoke(app, [str(a) for a in args])
        assert result.exit_code == 0, result.output
    return base / "one", base / "two"


def parts(out: Path, name: str = "points.parquet") -> list[str]:
    return sorted(p.name for p in (out / name).iterdir())


def report_of(out: Path) -> dict:
    report = json.loads((out / "ingest_report.json").read_text())
    return {k: v for k, v in report.items() if k not in TIMINGS}


def assert_same_outputs(a: Path, b: Path) -> None:
    """The same points and reports (row for row), tracks, vessels, routes, rejects and report
    counts (compared by pandas, for which a NaN heading equals NaN)."""
    for name in ("points.parquet", "reports.parquet"):
        table_a, table_b = (pq.read_table(d / name).to_pandas() for d in (a, b))
        assert len(table_a) > 0 and parts(a, name) == parts(b, name)
        assert table_a.equals(table_b), name  # in the same order, part by part
    for name in ("tracks.parquet", "vessels.parquet", "routes.parquet"):
        if (a / name).exists() or (b / name).exists():
            assert pq.read_table(a / name).equals(pq.read_table(b / name)), name
            assert pq.read_schema(a / name).metadata == pq.read_schema(b / name).metadata
    if (a / "routes.geojson").exists():
        assert (a / "routes.geojson").read_text() == (b / "routes.geojson").read_text()
    if (a / "rejects.parquet").exists():
        rejects_a, rejects_b = (pq.read_table(d / "rejects.parquet").to_pandas() for d in (a, b))
        assert len(rejects_a) and rejects_a.equals(rejects_b)  # NaN SOG/COG equal to NaN
    assert report_of(a) == report_of(b)


def temporaries(out: Path) -> list[str]:
    return sorted(p.name for p in out.iterdir() if p.name.startswith("."))


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


# --------------------------------------------------------------- the same outputs on workers
def test_kitimat_on_two_local_workers_gives_the_outputs_of_one_process(kitimat_runs):
    one, two = kitimat_runs
    assert_same_outputs(one, two)
    assert report_of(one)["tracks"]["total"] == 158


def test_the_ny_week_on_a_cluster_gives_the_outputs_of_one_process(cli, tmp_path, cluster):
    one = ingest(cli, tmp_path / "one", NY_WEEK, *NY_WEEK_ARGS)
    two = ingest(cli, tmp_path / "two", NY_WEEK, *NY_WEEK_ARGS, "--workers", cluster)
    assert one["tracks"]["total"] == two["tracks"]["total"] == 2144
    assert_same_outputs(tmp_path / "one", tmp_path / "two")


def test_many_sources_and_split_partitions_give_the_same_outputs(tmp_path, cluster, monkeypatch):
    """Kitimat cut into three files (three read tasks), three vessel partitions each too large
    for a piece (split by vessel and time inside its task): the same outputs, parts and ids."""
    header, *lines = gzip.decompress(KITIMAT.read_bytes()).splitlines(keepends=True)
    third = -(-len(lines) // 3)
    inputs = []
    for k in range(3):
        inputs.append(tmp_path / f"kitimat-{k}.csv")
        inputs[-1].write_bytes(header + b"".join(lines[k * third : (k + 1) * third]))
    monkeypatch.setattr(pipeline, "MAX_PARTITIONS", 3)
    plans, plan_pieces = [], partition.plan_pieces

    def spy(*args):  # sees the plans of this process's run only
        plans.append(plan_pieces(*args))
        return plans[-1]

    monkeypatch.setattr(partition, "plan_pieces", spy)
    settings = IngestSettings(
        min_points=100, rows_per_bucket=12_000, clusters="direction", keep_rejects=True
    )
    runs = {}
    for name, execution in (("one", Execution()), ("two", Execution(scheduler=cluster))):
        result = pipeline.ingest(inputs, tmp_path / name, settings, None, "none", None, execution)
        runs[name] = result.counts.as_dict()
    # in this process: each partition split, its tracks' reports and all its reports
    assert len(plans) == 6 and all(plan.count > 1 for plan in plans)
    assert len(runs["one"]["files"]) == 3 and runs["one"] == runs["two"]
    assert parts(tmp_path / "one") == [f"part-{k:05d}.parquet" for k in range(3)]
    assert len(parts(tmp_path / "one", "rejects.parquet")) == 6  # 3 sources, 3 partitions
    assert_same_outputs(tmp_path / "one", tmp_path / "two")
    ids = pq.read_table(tmp_path / "two" / "tracks.parquet").column("track_id").to_pylist()
    assert ids == list(range(len(ids)))


# ----------------------------------------------------------- points.parquet, a Parquet dataset
def test_the_points_dataset_reads_with_duckdb_pandas_pyarrow_and_geopandas(kitimat_runs):
    _, out = kitimat_runs
    points = out / "points.parquet"
    want = pq.read_table(points)
    report = json.loads((out / "ingest_report.json").read_text())
    assert report["outputs"]["points"] == str(points) and want.num_rows == report["kept_points"]
    got = duckdb.sql(f"SELECT * FROM read_parquet('{points}/*.parquet')").arrow()
    got = got.read_all() if isinstance(got, pa.RecordBatchReader) else got
    order = [("track_id", "ascending"), ("time", "ascending")]
    got, sorted_want = got.cast(want.schema).sort_by(order), want.sort_by(order)  # tz: Etc/UTC
    assert got.to_pandas().equals(sorted_want.to_pandas())  # (pandas: NaN heading equals NaN)
    assert ds.dataset(points, format="parquet").count_rows() == want.num_rows
    frame = pd.read_parquet(points)
    assert len(frame) == want.num_rows and list(frame.columns) == want.column_names
    located = gpd.GeoDataFrame(frame, geometry=gpd.points_from_xy(frame.lon, frame.lat), crs=4326)
    assert located.geometry.within(shapely.box(-131, 52, -127, 55)).all()  # around Kitimat
    tracks = gpd.read_parquet(out / "tracks.parquet")
    assert len(tracks) == report["tracks"]["total"] and tracks.crs == "OGC:CRS84"
    assert (tracks.geom_type == "LineString").all()
    assert tracks["n_points"].sum() == want.num_rows


def test_tracks_load_from_the_dataset_and_from_one_file(kitimat_runs, tmp_path):
    """`load_tracks` reads a points dataset, and one points.parquet file (what evaluate's data
    and earlier versions of ingest hold): the same tracks."""
    _, out = kitimat_runs
    single = tmp_path / "single"
    single.mkdir()
    shutil.copy(out / "tracks.parquet", single)
    pq.write_table(pq.read_table(out / "points.parquet"), single / "points.parquet")
    ids = [0, 57, 157]
    for a, b in zip(load_tracks(out, ids), load_tracks(single, ids), strict=True):
        assert a.track_id == b.track_id and (a.positions == b.positions).all()
        assert (a.dts == b.dts).all() and a.positions.shape[0] > 100


# ---------------------------------------------------------------- all or nothing, on workers
def test_a_failed_run_on_workers_leaves_the_earlier_set(cli, kitimat_runs, tmp_path):
    """A source that breaks mid-file fails its task on a worker: one line, and the folder holds
    the earlier run's set, byte for byte, and no temporary."""
    out = tmp_path / "out"
    shutil.copytree(kitimat_runs[0], out)
    before = snapshot(out)
    broken = tmp_path / "broken.csv.gz"
    broken.write_bytes(KITIMAT.read_bytes()[: KITIMAT.stat().st_size // 2])
    result = cli(
        "ingest", "--input", KITIMAT, "--input", broken, "--out", out, *KITIMAT_ARGS,
        "--workers", "2",
    )  # fmt: skip
    one_line_error(result, "broken.csv.gz: corrupt or truncated input")
    assert snapshot(out) == before and temporaries(out) == []


def test_ctrl_c_during_a_run_on_workers_leaves_the_earlier_set(kitimat_runs, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(kitimat_runs[0], out)
    before = snapshot(out)
    command = "import sys; from aisdati.cli import app; sys.argv[0] = 'aisdati'; app()"
    args = ["ingest", "--input", NY_WEEK, "--out", out, *NY_WEEK_ARGS, "--workers", "2"]
    proc = subprocess.Popen(
        [sys.executable, "-c", command, *[str(a) for a in args]],
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    deadline = time.monotonic() + 60
    while not list(out.glob(".ingest-*/*")):  # the tasks have begun (and spill till the end)
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert snapshot(out) == before and temporaries(out) == []


# ------------------------------------------------------------ dataset folders in the out set
def land(out: Path, files: dict[str, bytes]) -> None:
    """Commit a set of files (names relative to --out) as ingest does, points.parquet a dataset."""
    owned = ("points.parquet", "tracks.parquet", "ingest_report.json")
    with staged_outputs(out, owned, "ingest_report.json", datasets=["points.parquet"]) as staged:
        for name, data in files.items():
            (staged.folder / name).parent.mkdir(parents=True, exist_ok=True)
            (staged.folder / name).write_bytes(data)
        staged.commit()


def test_a_dataset_replaces_the_earlier_one_whole(tmp_path):
    """Fewer parts than the earlier run's: none of its parts is left; an earlier single file
    gives way to a folder and a folder to a single file the same way."""
    out = tmp_path / "out"
    land(out, {f"points.parquet/part-0000{k}.parquet": b"old" for k in range(3)})
    land(out, {"points.parquet/part-00000.parquet": b"new", "ingest_report.json": b"{}"})
    assert parts(out) == ["part-00000.parquet"] and temporaries(out) == []
    assert (out / "points.parquet" / "part-00000.parquet").read_bytes() == b"new"
    land(out, {"points.parquet": b"one file", "ingest_report.json": b"{}"})
    assert (out / "points.parquet").read_bytes() == b"one file"
    land(out, {"points.parquet/part-00000.parquet": b"parts", "tracks.parquet": b"t"})
    assert parts(out) == ["part-00000.parquet"] and not (out / "ingest_report.json").exists()
    land(out, {"tracks.parquet": b"t"})  # a run that writes no points: the earlier ones go
    assert sorted(p.name for p in out.iterdir()) == ["tracks.parquet"]


def test_a_folder_of_other_files_at_a_dataset_name_is_refused(cli, tmp_path):
    out = tmp_path / "out"
    (out / "points.parquet").mkdir(parents=True)
    (out / "points.parquet" / "notes.txt").write_text("mine")
    result = cli("ingest", "--input", NY_WEEK, "--out", out, *NY_WEEK_ARGS)
    one_line_error(result, "points.parquet there is a folder holding other files")
    assert (out / "points.parquet" / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in out.iterdir()) == ["points.parquet"]
