"""Event quality without a model: how the model-free event finders (`aisdati.events.find`) find
stretches injected into real tracks (`aisdati.evaluation.inject`), per kind and area, plain and
with every track thinned to one report per 10 minutes (`aisdati evaluate --thin 10min`).

For each ingest output given, each thinning and each seed: a seeded share of the tracks
(`--share`) takes one anomaly of a kind (each kind on its own draw of tracks), the rest of the
tracks, untouched, are the normal ones; every track's reports, altered or not, go through
`find_events`. Seeds are pooled until each kind has `--min-anomalies` altered tracks (or
`--max-seeds` seeds). Per kind x area: anomalies, ROC AUC of the track score (the largest
strength of an event of the right kind, `aisdati.evaluation.metrics.RIGHT_EVENTS`; 0 if none)
against the untouched tracks, the share of altered tracks with any event, the share of
stretches an event of the right kind overlaps, right events per 100 untouched tracks and the
median distance in reports from the right event's start to the stretch's, each with its 95 %
bootstrap interval (`aisdati.evaluation.metrics.event_metrics`).

Positions-only files (NY Harbor, Virginia Beach, US coastal) have SOG/COG derived from their
positions at ingest (`ingest_report.json`'s `derived`): their reported motion agrees with the
positions by construction, which the table notes.

Ingest first, e.g.:
  .venv/bin/aisdati ingest --input ../shared/data/kitimat/AIS_2018_07-08_Kitimat.csv.gz \\
      --roi none --min-points 100 --out /tmp/evq/kitimat
Run: python benchmarks/events_quality.py /tmp/evq/kitimat /tmp/evq/nyharbor ...
     [--kinds shift,course-noise,speed-noise,gap,drift,jump] [--min-anomalies 200]
     [--max-seeds 10] [--share 0.5] [--thin none,10min] [--resamples 1000] [--json PATH]
     [--no-calibrate]
By default half the vessels' tracks calibrate the thresholds and say where traffic reports
ashore (as a model's training tracks do) and the other half are judged; `--no-calibrate`
judges every track with the defaults.
Not part of the test suite.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
from report import Report, add_json_option  # (this folder: run as a script)

from aisdati.evaluation.dataset import thinned
from aisdati.evaluation.inject import MIN_POINTS, inject
from aisdati.evaluation.metrics import EVENT_FIELDS, event_metrics
from aisdati.events.calibrate import calibrated, calibration
from aisdati.events.find import find_events
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.preprocess.settings import parse_duration
from aisdati.tracks.ashore import AshoreCheck

KINDS = "shift,course-noise,speed-noise,gap,drift,jump"
POSITIONS_ONLY = (
    "positions only: SOG/COG derived from positions at ingest (its reported motion agrees "
    "with its positions by construction; no heading, so no drift outside injected stretches)"
)


def tracks_of(data: Path, thin_s: float | None) -> list[VesselReports]:
    """Every track of an ingest output with at least `MIN_POINTS` reports (thinned)."""
    points = pd.read_parquet(data / "points.parquet").sort_values(["track_id", "time"])
    if thin_s is not None:
        points = points[thinned(pa.Table.from_pandas(points, preserve_index=False), thin_s)]
    return [
        VesselReports.of(g.assign(track_id=tid))
        for tid, g in points.groupby("track_id")
        if len(g) >= MIN_POINTS
    ]


def altered(v: VesselReports, kind: str, rng: np.random.Generator) -> tuple[VesselReports, tuple]:
    """The track with one anomaly of `kind`, and its stretch."""
    got = inject(kind, v.positions(), v.time_s - v.time_s[0], rng, None,
                 np.column_stack([v.sog, v.cog, v.heading]))  # fmt: skip
    n = len(got.positions)
    new = VesselReports(
        v.mmsi, v.time_s[0] + got.times_s, got.positions[:, 0], got.positions[:, 1],
        got.motion[:, 0], got.motion[:, 1], got.motion[:, 2], v.status[got.rows],
        np.full(n, v.track_id[0]),
    )  # fmt: skip
    return new, got.stretch


def events_of(key: str, v: VesselReports, judge: Judge) -> list[tuple]:
    found = find_events(v, judge.settings, seen=judge.seen)
    return [(key, e.kind, e.start, e.end, e.strength) for e in found]


@dataclass(frozen=True)
class Judge:
    """How tracks are judged: the thresholds and where the calibrating traffic reported ashore
    (as a model's card records it, `aisdati.tracks.ashore`)."""

    settings: EventSettings = field(default_factory=EventSettings)
    seen: np.ndarray | None = None


def calibrating(tracks: list[VesselReports]) -> tuple[list[VesselReports], list[VesselReports]]:
    """The tracks of every other vessel (by MMSI order) calibrate the thresholds, as a
    model's training tracks do in `aisdati detect` (`aisdati.events.calibrate`); the rest are
    judged."""
    vessels = sorted({v.mmsi for v in tracks})
    calibrates = set(vessels[::2])
    return [v for v in tracks if v.mmsi in calibrates], [
        v for v in tracks if v.mmsi not in calibrates
    ]


def one_kind(
    tracks: list[VesselReports], kind: str, args: argparse.Namespace, judge: Judge
) -> tuple[list[tuple], list[tuple], int]:
    """The altered tracks' labels and events of one kind, over seeds until enough."""
    labels, events, seeds = [], [], 0
    per_seed = max(1, round(args.share * len(tracks)))
    for seed in range(args.max_seeds):
        if len(labels) >= args.min_anomalies:
            break
        seeds += 1
        rng = np.random.default_rng([seed, len(kind), sum(map(ord, kind))])
        need = min(per_seed, args.min_anomalies - len(labels))
        for k in rng.permutation(len(tracks))[:need]:
            key = f"{seed}/{kind}/{k}"
            v, (start, end) = altered(tracks[k], kind, rng)
            labels.append((key, 1, kind, start, end))
            events += events_of(key, v, judge)
    return labels, events, seeds


def area_rows(data: Path, thin_s: float | None, args: argparse.Namespace) -> list[dict]:
    """`event_metrics`' rows of one area and thinning, each kind's seeds pooled."""
    tracks = tracks_of(data, thin_s)
    judge = Judge()
    if args.calibrate:
        calibrates, tracks = calibrating(tracks)
        seen = AshoreCheck().seen([v.positions() for v in calibrates])
        judge = Judge(calibrated(calibration(calibrates)), np.reshape(seen, (-1, 2)))
    labels = [(f"n{k}", 0, "", -1, -1) for k in range(len(tracks))]
    events = [e for k, v in enumerate(tracks) for e in events_of(f"n{k}", v, judge)]
    on_normal = pd.Series([e[1] for e in events], dtype=object).value_counts()
    by_kind = {k: round(100 * n / len(tracks), 1) for k, n in on_normal.items()}
    seeds = {}
    for kind in args.kinds:
        got_labels, got_events, seeds[kind] = one_kind(tracks, kind, args, judge)
        labels += got_labels
        events += got_events
    frame = pd.DataFrame(labels, columns=["track_id", "label", "kind", "start", "end"])
    found = pd.DataFrame(events, columns=list(EVENT_FIELDS))
    rows = event_metrics(frame, found, args.kinds, args.resamples)
    for r in rows:
        r.update(normal=len(tracks), seeds=seeds.get(r["kind"]), normal_events=by_kind)
    return rows


def derived(data: Path) -> bool:
    """Whether ingest derived SOG/COG from positions for a file it read (positions only)."""
    doc = json.loads((data / "ingest_report.json").read_text())
    return any(f.get("derived") for f in doc.get("files", []))


def cell(row: dict, name: str, fmt: str = "{:.2f}") -> str:
    value = row.get(name)
    if value is None:
        return "-"
    low, high = row.get(f"{name}_ci") or (None, None)
    return fmt.format(value) + (
        f" [{fmt.format(low)}, {fmt.format(high)}]" if low is not None else ""
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", type=Path, nargs="+", help="ingest output folders")
    parser.add_argument("--kinds", default=KINDS)
    parser.add_argument("--min-anomalies", type=int, default=200)
    parser.add_argument("--max-seeds", type=int, default=10)
    parser.add_argument("--share", type=float, default=0.5)
    parser.add_argument("--thin", default="none,10min")
    parser.add_argument("--resamples", type=int, default=1000)
    parser.add_argument(
        "--no-calibrate", dest="calibrate", action="store_false",
        help="judge with EventSettings' defaults (detect --models none) instead of thresholds "
        "calibrated on half the vessels (detect with a model)",
    )  # fmt: skip
    add_json_option(parser, "events_quality")
    args = parser.parse_args()
    args.kinds = [k.strip() for k in args.kinds.split(",")]
    thins = [None if t == "none" else parse_duration(t, "--thin") for t in args.thin.split(",")]
    columns = ["area", "thin", "kind", "anomalies", "seeds", "ROC AUC", "flagged",
               "right overlap", "false/100 normal", "start error (reports)"]  # fmt: skip
    with Report.from_args("events_quality", args) as report:
        for data in args.data:
            if derived(data):
                report.say(f"{data.name}: {POSITIONS_ONLY}")
        table = report.table(columns, title="Model-free events on injected stretches")
        for data in args.data:
            for thin_s in thins:
                t0 = time.perf_counter()
                rows = area_rows(data, thin_s, args)
                thin = "-" if thin_s is None else f"{thin_s / 60:g} min"
                every = next(r for r in rows if r["kind"] == "any")
                for r in rows:
                    if r["kind"] == "any":
                        continue
                    table.row(
                        [data.name, thin, r["kind"], r["anomalies"], r["seeds"],
                         cell(r, "roc_auc"), cell(r, "flagged"), cell(r, "overlapped"),
                         cell(r, "false_events_per_100", "{:.1f}"),
                         cell(r, "median_start_error", "{:.0f}")],
                        {**r, "area": data.name, "thin_s": thin_s},
                    )  # fmt: skip
                report.note(f"{data.name}, thin {thin}: {rows[0]['normal']} normal tracks, "
                            f"{cell(every, 'false_events_per_100', '{:.1f}')} events of any "
                            f"kind per 100 of them ({every['normal_events']}), "
                            f"{time.perf_counter() - t0:.0f} s")  # fmt: skip


if __name__ == "__main__":
    main()
