"""The busiest waters of the shipped US coastal day (`US_coastal_2020_06_30_points.csv.gz`) as
forward areas: how the forward areas of that day (Puget Sound, Los Angeles, San Francisco, and
six small ones from Boston to Tampa Bay) were chosen, by counts alone, before any detector ran on
them (docs/results/forward.md), and what the ashore rule (`aisdati.tracks.ashore`)
makes of each box's later tracks when the coastline holds its water as land.

For each box in `benchmarks/areas/*.geojson`: `aisdati ingest --roi BOX --min-points 20` (Virginia
Beach's setting), the tracks and vessels, the share of reports on land by the coastline
(`aisdati.coastline.on_land`), the whole hour at which about two thirds of the tracks have started
(the split), the tracks before and after it, and how many later tracks the ashore rule flags
without and with the water the earlier tracks sailed (`AshoreCheck.seen`, as a model's card
records it). No model is trained.

Run: python benchmarks/coastal_areas.py [--out runs/coastal-areas] [--json PATH]
(prints a markdown table, its rows as JSON in benchmarks/results/coastal_areas.json)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
from detection_quality import AREAS, FORWARD, ingest  # (this folder: run as a script)
from report import Report, add_json_option

from aisdati.coastline import on_land
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import load_tracks, read_track_table

DAY, MIN_POINTS = FORWARD["pugetsound"][:2]
"""The US coastal day and the fourth area's --min-points, for every box alike."""
TRAINING_SHARE = 2 / 3
"""The share of tracks before the split: about the other forward areas' training share."""


def split_hour(starts: pd.Series) -> pd.Timestamp:
    """The whole hour nearest the start of the track at `TRAINING_SHARE` of them."""
    ordered = starts.sort_values().reset_index(drop=True)
    return ordered.iloc[int(len(ordered) * TRAINING_SHARE)].round("h")


def row(box: Path, data: Path) -> tuple[list, dict]:
    """The box's cells as printed, and its measurements unformatted."""
    table = read_track_table(data)
    tracks = load_tracks(data, table["track_id"].tolist())
    positions = [t.positions for t in tracks]
    reports = np.concatenate(positions)
    land = float(on_land(reports[:, 0], reports[:, 1]).mean())
    split = split_hour(table["start"])
    before = (table["start"] < split).to_numpy()
    rule = AshoreCheck()
    earlier = [p for p, b in zip(positions, before, strict=True) if b]
    later = [p for p, b in zip(positions, before, strict=True) if not b]
    seen = np.asarray(rule.seen(earlier), np.float64).reshape(-1, 2)
    plain = int(rule.flags(rule.counts(later)).sum())
    excused = int(rule.flags(rule.counts(later, seen)).sum())
    cells = [box.stem, len(table), table["mmsi"].nunique(), f"{land:.3f}", f"{split:%H:%M}"]
    cells += [int(before.sum()), len(later), plain, excused]
    keys = ("box", "tracks", "vessels", "reports_on_land", "split", "before", "after")
    values = dict(zip(keys, [*cells[:3], land, split.isoformat(), *cells[5:7]], strict=True))
    return cells, {**values, "later_ashore": plain, "later_ashore_with_seen_water": excused}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("runs/coastal-areas"))
    add_json_option(ap, "coastal_areas")
    args = ap.parse_args()
    with Report.from_args("coastal_areas", args) as report:
        columns = ["box", "tracks", "vessels", "reports on land", "split (UTC)", "before",
                   "after", "later tracks ashore", "with the earlier tracks' water"]  # fmt: skip
        table = report.table(columns, title="The US coastal day's boxes as forward areas")
        for box in sorted(AREAS.glob("*.geojson")):
            data = args.out / box.stem
            ingest(DAY, MIN_POINTS, data, str(box))
            table.row(*row(box, data))


if __name__ == "__main__":
    main()
