"""The fleet kinds live as in batch, from the command line: real traffic with one constructed
case written in (`aisdati.evaluation.constructed.CONSTRUCTORS`) is logged as NMEA, and both
ingest + `detect --models none` and `aisdati watch` on that feed find the case, naming its
vessels, and end with the same events.

The traffic is cut so that each test takes seconds: the New York Harbor hour's 80 busiest
vessels (an interference, a gap heard, a gap quiet), and the two Kitimat vessels of an
encounter over the hours around it. The watch judges 3-hour windows, looks for the fleet kinds
every 30 minutes of the feed and once more where the feed ends (`Watch.end`): on the NY
feeds, all shorter than a window, that last look sees what detect sees. The encounter (3.8 h,
longer than a window) is replayed paced (`--speed`, chunks of a few lines), as a live feed
comes: the scans during the meeting find it, and it keeps the start it was first found with
(`aisdati.live.ledger`); read in one chunk, only the last window's 2 hours of it would be
seen, and no encounter of 2 hours within 500 m found there. A
position jump or report ashore is raised, then withdrawn at the next scan that finds the
interference explaining it (docs/usage/watch.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from aisdati.evaluation.constructed import CONSTRUCTORS, Case, found
from aisdati.events.anchorages import learned_from
from aisdati.events.fleet import named
from aisdati.events.kinds import KINDS
from aisdati.tracks.reports import read_reports, read_vessels
from tests.helpers.meetings import met
from tests.helpers.nmea import as_nmea, detected_and_watched

BUSIEST = 80
COMPARED = ["kind", "mmsi", "start", "end", "coverage"]


def written(processed: Path, name: str, seed: int) -> tuple[pd.DataFrame, pd.DataFrame, Case]:
    """The NY hour's `BUSIEST` vessels with the first case `name`'s constructor writes in from
    `seed` on."""
    reports, identity = read_reports(processed), read_vessels(processed)
    reports = reports[reports["mmsi"].isin(reports["mmsi"].value_counts().index[:BUSIEST])]
    for s in range(seed, seed + 400):
        if (built := CONSTRUCTORS[name](reports, identity, np.random.default_rng(s))) is not None:
            return built
    raise AssertionError(f"no place for a {name} case")


def same_events(batch: pd.DataFrame, live: pd.DataFrame) -> None:
    """Both end with the same events: kind, vessel, span, coverage, and the vessels named."""

    def key(frame: pd.DataFrame) -> list[tuple]:
        rows = frame.assign(
            named=frame.apply(lambda e: tuple(sorted(named(e))), axis=1),
            coverage=frame["coverage"].where(frame["coverage"].notna(), None),
        )
        return sorted(map(tuple, rows[[*COMPARED, "named"]].astype(str).to_numpy()))

    assert key(batch) == key(live)


def test_watch_finds_a_constructed_encounter_as_detect(kitimat, tmp_path):
    reports, identity, case = met(kitimat, seed=3)
    hours = pd.Timedelta(hours=1)
    cut = reports[reports["mmsi"].isin(case.mmsis) & (reports["time"] >= case.start - hours)
                  & (reports["time"] <= case.end + hours)]  # fmt: skip
    feed = as_nmea(cut, identity, tmp_path / "feed.nmea")
    batch, live, _ = detected_and_watched(feed, tmp_path, "--speed", "1e9")
    assert found(case, batch) and found(case, live)
    same_events(batch, live)


@pytest.mark.parametrize("seed", [0, 1])
def test_watch_finds_a_constructed_interference_as_detect_its_jumps_withdrawn(
    processed, tmp_path, seed
):
    """Seed 0's block has a vessel whose displaced reports ingest takes for a second
    transmitter's (split off under MMSI + 1000000000): the interference reads an MMSI's two
    transmitters as one vessel, names it, and folds the conflict they seemed."""
    reports, identity, case = written(processed, "gnss-interference", seed=seed)
    nmea = as_nmea(reports, identity, tmp_path / "feed.nmea")
    batch, live, changes = detected_and_watched(nmea, tmp_path)
    assert found(case, batch) and found(case, live)
    same_events(batch, live)
    (area,) = live.loc[live["kind"] == "gnss-interference", "event_id"]
    withdrawn = [c for c in changes if c["change"] == "withdrawn"]
    assert withdrawn  # raised by one vessel's judgement before the scan that explains it
    for c in withdrawn:
        assert c["into"] == area and c["kind"] in KINDS["gnss-interference"].folds
        assert c["mmsi"] in case.mmsis and c["event_id"] not in set(live["event_id"])


def test_watch_finds_a_constructed_port_visit_as_detect_given_the_ports(kitimat, tmp_path):
    """A visit lasts 3 hours or more (3.5-12 h here): the watch finds it with a window longer
    than the stay (`--window 16h`; the default 3 h holds none whole). Both are given the same
    ports (`--ports`: the anchorages of the whole of Kitimat, as an analyst gives a port list),
    which a few vessels' hours could not learn."""
    reports, identity = read_reports(kitimat), read_vessels(kitimat)
    made = (
        CONSTRUCTORS["port-visit"](reports, identity, np.random.default_rng(s)) for s in range(40)
    )
    out, identity, case = next(m for m in made if m is not None)
    hours = pd.Timedelta(hours=2)
    cut = out[out["mmsi"].isin(case.mmsis) & (out["time"] >= case.start - hours)
              & (out["time"] <= case.end + hours)]  # fmt: skip
    ports = tmp_path / "ports.geojson"
    ports.write_text(json.dumps(learned_from(reports).geojson()))
    feed = as_nmea(cut, identity, tmp_path / "feed.nmea")
    batch, live, _ = detected_and_watched(feed, tmp_path, "--speed", "1e9", "--window", "16h",
                                          ports=ports)  # fmt: skip
    assert found(case, batch) and found(case, live)
    same_events(batch, live)


@pytest.mark.parametrize("name", ["gap-heard", "gap-quiet"])
def test_watch_says_a_gaps_coverage_as_detect(processed, tmp_path, name):
    reports, identity, case = written(processed, name, seed=0)
    batch, live, _ = detected_and_watched(as_nmea(reports, identity, tmp_path / "feed.nmea"),
                                          tmp_path)  # fmt: skip
    assert found(case, batch) and found(case, live)
    same_events(batch, live)
