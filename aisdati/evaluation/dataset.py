"""The evaluation's data set: a seeded split of one group's tracks by vessel (or by time: the
tracks that start before a date train, the later ones are judged, as an analyst uses a model
month after month), anomalies written into a share of the held-out tracks (half by default), all
saved in ingest's own schema (points.parquet,
tracks.parquet) with `labels.csv` beside them, so `aisdati train` and `aisdati detect` read it
like any ingest output. An altered track's reported motion (sog, cog, heading where the
reports have it) is what its kind says it reports (`aisdati.evaluation.inject`); untouched
tracks keep theirs. With `thin_s`, every track is first thinned to one report per `thin_s`
seconds, so each kind is also measured where one report moves a vessel kilometres."""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import shapely

from aisdati.errors import UserError
from aisdati.evaluation.inject import MIN_POINTS, Injected, inject
from aisdati.geo import legs_m
from aisdati.outdir import atomic_write_bytes, parquet_bytes
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.schema import UTC_US
from aisdati.tracks.store import read_track_table, select_cluster

MIN_SPLIT = 4
"""Each side of the split needs at least this many tracks (and the held-out side twice this,
half of it to take anomalies)."""


@dataclass
class Split:
    train_ids: list[int]
    heldout_ids: list[int]
    """Held-out tracks kept normal, and (after injection) the new ids of the altered ones."""
    labels: pd.DataFrame
    """track_id, label (0/1), kind ('' for normal), source_track_id, start, end (the altered
    stretch's [start, end) report indices)."""
    not_at_sea: list[int] = field(default_factory=list)
    """With `at_sea`: tracks drawn to take an anomaly that no draw kept at sea (left normal)."""


AT_SEA_DRAWS = 50
"""`at_sea`: anomalies drawn per track (each with new parameters) before it is left normal."""


def _anomaly(
    kind: str,
    pos: np.ndarray,
    times_s: np.ndarray,
    motion: np.ndarray,
    rng: np.random.Generator,
    params: dict,
    at_sea: bool,
) -> Injected | None:
    """One anomaly of `kind` written into a track; with `at_sea`, the first of `AT_SEA_DRAWS`
    draws that puts no more reports ashore (`aisdati.tracks.ashore`) than the track had, so
    that what is measured is what a vessel could sail; None when none does."""
    if not at_sea:
        return inject(kind, pos, times_s, rng, params, motion)
    rule = AshoreCheck()
    before = int(rule.reports(pos).sum())
    for _ in range(AT_SEA_DRAWS):
        got = inject(kind, pos, times_s, rng, params, motion)
        if int(rule.reports(got.positions).sum()) <= before:
            return got
    return None


def split_by_vessel(
    table: pd.DataFrame, train_fraction: float, seed: int
) -> tuple[list[int], list[int]]:
    """Vessels in seeded random order go to training until it holds `train_fraction` of the
    tracks: no vessel is on both sides."""
    rng = np.random.default_rng(seed)
    vessels = np.sort(table["mmsi"].unique())
    counts = table.groupby("mmsi").size()
    target = train_fraction * len(table)
    train_v: list[int] = []
    have = 0
    for v in rng.permutation(vessels):
        if have >= target:
            break
        train_v.append(int(v))
        have += int(counts[v])
    is_train = table["mmsi"].isin(train_v)
    return (
        sorted(int(i) for i in table.loc[is_train, "track_id"]),
        sorted(int(i) for i in table.loc[~is_train, "track_id"]),
    )


def split_by_time(table: pd.DataFrame, before: pd.Timestamp) -> tuple[list[int], list[int]]:
    """Tracks that start before `before` train, the others are judged (the same vessels may
    sail on both sides, as they do month after month)."""
    early = pd.to_datetime(table["start"], utc=True) < before
    return (
        sorted(int(i) for i in table.loc[early, "track_id"]),
        sorted(int(i) for i in table.loc[~early, "track_id"]),
    )


def build(
    data_dir: Path,
    cluster: str,
    out: Path,
    kinds: tuple[str, ...],
    params: dict,
    train_fraction: float = 0.6,
    seed: int = 0,
    train_ids: list[int] | None = None,
    before: pd.Timestamp | None = None,
    altered: float = 0.5,
    at_sea: bool = False,
    thin_s: float | None = None,
) -> Split:
    """Split, inject and write the evaluation data set to `out`; see the module docstring.
    `before`: split by time instead of by vessel; `altered`: the share of the held-out tracks
    that take an anomaly; `at_sea`: only anomalies that keep the track off the land
    (`_anomaly`); `thin_s`: every track thinned to one report per `thin_s` seconds first."""
    table = select_cluster(read_track_table(data_dir), cluster, data_dir)
    points, tracks, next_id = _read_sides(data_dir, [int(i) for i in table["track_id"]], thin_s)
    sizes = pd.Series(points["track_id"].to_numpy()).value_counts()
    table = table[table["track_id"].map(sizes).fillna(0) >= MIN_POINTS]
    train, held = _sides(table, train_fraction, seed, train_ids, before)
    _check_sides(table, cluster, train, held, before)
    assign = _kinds_of_altered(held, kinds, altered, seed)
    used = pa.array(train + held, pa.int64())
    points = points.filter(pc.is_in(points["track_id"], used))
    tracks = tracks.filter(pc.is_in(tracks["track_id"], used))
    changed = pc.invert(pc.is_in(points["track_id"], pa.array(list(assign), pa.int64())))
    keep_pts = [points.filter(changed)]
    keep_trk = [tracks.filter(pc.invert(pc.is_in(tracks["track_id"], pa.array(list(assign)))))]
    rows = [(tid, 0, "", tid, -1, -1) for tid in held if tid not in assign]
    alt_pts, alt_trk, alt_rows, not_at_sea = _with_anomalies(
        points, tracks, assign, next_id, seed, params, at_sea
    )
    labels = pd.DataFrame(
        rows + alt_rows, columns=["track_id", "label", "kind", "source_track_id", "start", "end"]
    ).sort_values("track_id", kind="stable")
    points = pa.concat_tables(keep_pts + alt_pts)
    _write(out, points, _redrawn(pa.concat_tables(keep_trk + alt_trk), points), labels)
    heldout = sorted(int(i) for i in labels["track_id"])
    return Split(train, heldout, labels.reset_index(drop=True), not_at_sea)


def _sides(
    table: pd.DataFrame,
    train_fraction: float,
    seed: int,
    train_ids: list[int] | None,
    before: pd.Timestamp | None,
) -> tuple[list[int], list[int]]:
    """The training and held-out track ids: by time with `before`, else by vessel. Given the
    models' own training tracks (`train_ids`), those of the group train; split by time, the
    later others are held out, whatever the dates of those that train; split by vessel, the
    tracks of the vessels none of them belongs to."""
    if before is not None:
        train, held = split_by_time(table, before)
        if train_ids is not None:  # the models' own training tracks, whatever their dates
            train = sorted(set(train_ids) & set(table["track_id"]))
            held = sorted(set(held) - set(train))
        return train, held
    if train_ids is None:
        return split_by_vessel(table, train_fraction, seed)
    train = sorted(set(train_ids) & set(table["track_id"]))
    vessels = set(table.loc[table["track_id"].isin(train), "mmsi"])
    held = sorted(int(i) for i in table.loc[~table["mmsi"].isin(vessels), "track_id"])
    return train, held


def _check_sides(
    table: pd.DataFrame,
    cluster: str,
    train: list[int],
    held: list[int],
    before: pd.Timestamp | None,
) -> None:
    """A `UserError` unless each side has enough tracks (`MIN_SPLIT`)."""
    if len(train) < MIN_SPLIT or len(held) < 2 * MIN_SPLIT:
        sides = "before and from the date" if before is not None else "from different vessels"
        raise UserError(
            f"cluster {cluster!r} has {len(table)} tracks of at least {MIN_POINTS} reports "
            f"({len(train)} for training, {len(held)} held out); evaluate needs at least "
            f"{MIN_SPLIT} for training and {2 * MIN_SPLIT} held out ({sides})"
        )


def _kinds_of_altered(
    held: list[int], kinds: tuple[str, ...], altered: float, seed: int
) -> dict[int, str]:
    """The held-out tracks that take an anomaly (a seeded share `altered` of them, at least
    one), each with its kind: the kinds in turn, in the seeded order the tracks were drawn."""
    rng = np.random.default_rng([seed, 1])
    order = [held[i] for i in rng.permutation(len(held))]
    chosen = order[: max(1, round(len(held) * altered))]
    return {tid: kinds[k % len(kinds)] for k, tid in enumerate(chosen)}


def _read_sides(
    data_dir: Path, ids: list[int], thin_s: float | None
) -> tuple[pa.Table, pa.Table, int]:
    """The reports (by track and time, thinned with `thin_s`) and the tracks.parquet rows of
    the tracks `ids`, and the first track id that no track of the ingest output has (the
    altered tracks' ids)."""
    points = pq.read_table(data_dir / "points.parquet", filters=[("track_id", "in", ids)]).sort_by(
        [("track_id", "ascending"), ("time", "ascending")]
    )
    if thin_s is not None:
        points = points.filter(thinned(points, thin_s))
    tracks = pq.read_table(data_dir / "tracks.parquet")
    next_id = int(pc.max(tracks["track_id"]).as_py()) + 1
    tracks = tracks.filter(pc.is_in(tracks["track_id"], pa.array(ids, pa.int64())))
    return points, tracks, next_id


def thinned(points: pa.Table, every_s: float) -> np.ndarray:
    """Which reports (sorted by track and time) a track keeps at one report per `every_s`
    seconds: its first, then each that comes `every_s` or more after the last one kept."""
    track = points["track_id"].to_numpy()
    t = points["time"].cast(pa.int64()).to_numpy() / 1e6
    keep = np.zeros(len(t), bool)
    last_track, last_t = None, 0.0
    for k in range(len(t)):
        if track[k] != last_track or t[k] - last_t >= every_s:
            keep[k] = True
            last_track, last_t = track[k], t[k]
    return keep


def _redrawn(tracks: pa.Table, points: pa.Table) -> pa.Table:
    """The tracks' rows, each whose reports were thinned (fewer than its `n_points`) redrawn
    from those it keeps."""
    sizes = pd.Series(points["track_id"].to_numpy()).value_counts()
    rows = []
    for k, (tid, n) in enumerate(
        zip(tracks["track_id"].to_pylist(), tracks["n_points"].to_pylist(), strict=True)
    ):
        row = tracks.slice(k, 1)
        if sizes.get(tid, n) != n:
            row = _track_row(row, tid, points.filter(pc.equal(points["track_id"], tid)), None)
        rows.append(row)
    return pa.concat_tables(rows) if rows else tracks


def _with_anomalies(
    points: pa.Table,
    tracks: pa.Table,
    assign: dict[int, str],
    next_id: int,
    seed: int,
    params: dict,
    at_sea: bool,
) -> tuple[list[pa.Table], list[pa.Table], list[tuple], list[int]]:
    """The tracks of `assign` (id -> kind) in the order of their ids, the k-th with an anomaly
    written in (`_altered`, its generator seeded with `seed` and k) as track `next_id + k`, or
    left as it is where no draw kept it at sea: their reports, rows of tracks.parquet and rows
    of labels.csv, and the ids of those left."""
    new_pts, new_trk, rows, not_at_sea = [], [], [], []
    for k, src in enumerate(sorted(assign)):
        kind = assign[src]
        pts = points.filter(pc.equal(points["track_id"], src))
        source_row = tracks.filter(pc.equal(tracks["track_id"], src))
        rng_k = np.random.default_rng([seed, 2, k])
        written = _altered(pts, source_row, kind, next_id + k, rng_k, params, at_sea)
        if written is None:  # counted, and judged as the normal track it is
            not_at_sea.append(src)
            new_pts.append(pts)
            new_trk.append(source_row)
            rows.append((src, 0, "", src, -1, -1))
            continue
        altered_pts, altered_row, got = written
        new_pts.append(altered_pts)
        new_trk.append(altered_row)
        rows.append((next_id + k, 1, kind, src, *got.stretch))
    return new_pts, new_trk, rows, not_at_sea


def _altered(
    pts: pa.Table,
    source_row: pa.Table,
    kind: str,
    new_id: int,
    rng: np.random.Generator,
    params: dict,
    at_sea: bool,
) -> tuple[pa.Table, pa.Table, Injected] | None:
    """A track (its reports `pts`, its row `source_row`) with an anomaly of `kind` written in,
    as track `new_id`: its reports, its row of tracks.parquet and the anomaly; None where no
    draw kept it at sea (`_anomaly`)."""
    pos = np.column_stack([pts["lon"].to_numpy(), pts["lat"].to_numpy()])
    t_us = pts["time"].cast(pa.int64()).to_numpy()
    t0 = int(t_us[0])
    motion = np.column_stack([_floats(pts, name) for name in MOTION])
    got = _anomaly(kind, pos, (t_us - t0) / 1e6, motion, rng, params, at_sea)
    if got is None:
        return None
    new_pts = _points(pts, new_id, t0, got)
    return new_pts, _track_row(source_row, new_id, new_pts, "inject"), got


MOTION = ("sog", "cog", "heading")
"""The reported motion an anomaly rewrites, in `Injected.motion`'s order."""


def _floats(pts: pa.Table, name: str) -> np.ndarray:
    """A column as float64, NaN where null or where the reports do not have it."""
    if name not in pts.column_names:
        return np.full(pts.num_rows, np.nan)
    return pc.fill_null(pts[name].cast(pa.float64()), np.nan).to_numpy()


def _points(pts: pa.Table, track_id: int, t0_us: int, got: Injected) -> pa.Table:
    """The altered track's reports in the source's schema: positions, times and reported
    motion from the anomaly, every other field from each report's source report."""
    n = len(got.positions)
    time_us = t0_us + np.round(got.times_s * 1e6).astype(np.int64)
    new = {
        "track_id": np.full(n, track_id, np.int64),
        "time": pa.array(time_us).view(UTC_US),
        "lon": got.positions[:, 0],
        "lat": got.positions[:, 1],
        **{name: got.motion[:, k] for k, name in enumerate(MOTION)},
    }
    source = pts.take(pa.array(got.rows, pa.int64()))
    columns = []
    for field_ in pts.schema:
        if field_.name not in new:
            columns.append(source[field_.name])
            continue
        values = new[field_.name]
        if pa.types.is_integer(field_.type) and field_.name in MOTION:
            values = np.round(values)
        columns.append(pa.array(values, from_pandas=True).cast(field_.type, safe=False))
    return pa.table(columns, schema=pts.schema)


def _track_row(row: pa.Table, track_id: int, pts: pa.Table, stage: str | None) -> pa.Table:
    """The source track's row (cluster, route, ...) redrawn from its new reports `pts`, and
    its `stage` where given."""
    p = np.column_stack([pts["lon"].to_numpy(), pts["lat"].to_numpy()])
    changes = {
        "track_id": pa.array([track_id], pa.int64()),
        "end": pa.array([pts["time"][-1].as_py()], row.schema.field("end").type),
        "n_points": pa.array([len(p)], pa.int64()),
        "length_km": pa.array([float(legs_m(p).sum()) / 1000.0]),
        "geometry": pa.array([shapely.to_wkb(shapely.linestrings(p))], pa.binary()),
    }
    if stage is not None:
        changes["stage"] = pa.array([stage])
    for name, value in changes.items():
        if name in row.column_names:
            i = row.column_names.index(name)
            row = row.set_column(i, row.schema.field(i), value.cast(row.schema.field(i).type))
    return row


def _write(out: Path, points: pa.Table, tracks: pa.Table, labels: pd.DataFrame) -> None:
    out.mkdir(parents=True, exist_ok=True)
    points = points.sort_by([("track_id", "ascending"), ("time", "ascending")])
    tracks = tracks.sort_by("track_id")
    for name, table in (("points.parquet", points), ("tracks.parquet", tracks)):
        atomic_write_bytes(out / name, parquet_bytes(table))
    buf = io.StringIO()
    labels.to_csv(buf, index=False)
    atomic_write_bytes(out / "labels.csv", buf.getvalue().encode())
