"""A third signal for the area model, measured on forward grids (not a test, not in the tool).

A track's winding is the total rotation of its heading: the sum over its reports of the change of
course between consecutive moves, each wrapped to (-180, 180], in absolute value (degrees). The
sum telescopes, so back-and-forth noise cancels, a turn onto a new course counts its angle, and
each full circle adds 360: a loitering circle, which the one-step score and the distance to the
traffic both pass at sea (`benchmarks/step_traffic.py`, "either"), winds 360-720 degrees more than
the track it was written into. It has no parameter and is calibrated on the training tracks
themselves.

For each cell of `benchmarks/detection_quality.py --forward --detectors dati,nearest`, it
computes the winding of the judged tracks (data/points.parquet) and of the training tracks (the
nearest model's kept tracks), then prints per grid the nine-cell means of: the ROC AUC of winding
alone; "either2", a track flagged when the one-step score or nearest's lane passes its own 95 %
training quantile; and "either3", flagged when any of step, lane and winding passes its training
quantile q, with one q for the three chosen so that 5 % of the training tracks are flagged. FA /
recall as in step_traffic.py (the ashore rule's flags included).

`--signal crossings` measures instead how many times a track crosses its own path (pairs of
non-adjacent segments that intersect): a loitering circle closes a loop, a harbour turn-around
turns as far without closing one.

`--signal local --within KM` takes the largest |rotation| over any stretch of at most KM of the
track's length: a circle closes within its circumference, a harbour turn-around spreads its
turns over the whole track. `--signal place --within KM` takes how much more the track turns
within KM than the training traffic turned within KM of the same place (`PlaceTurning`): a tug
that works in one corner of a harbour makes turning normal there, not across the ferries' lane.

`--signal excess` takes how much longer the track sailed than it had to (`PathExcess`): its length
less the shortest way between its two ends along the training traffic. A detour, a loiter or a
jump lengthens a track without moving its ends; a normal track on a path no vessel sailed before,
the later months' tail that passes the other terms' thresholds, is not longer for it.
`--signal split` sums that excess over the two halves of the track cut at its report farthest
from its first: a round trip's ends coincide, so all of its length would be excess.

`--signal speed` takes a track's top speed, the largest implied speed between consecutive reports:
a position jump moves a stretch several kilometres within one report interval. `--signal relspeed`
divides it by the track's median leg speed, so that a fast vessel is not a jump; `--signal spike`
by the faster of the leg's two neighbours', so that a boat speeding up is not one either.

Run: python benchmarks/winding.py runs/grid/*/forward-*
     [--signal winding|crossings|local|place|excess|split|speed|relspeed|spike] [--within KM]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import shapely
from scipy.spatial import cKDTree
from sklearn.metrics import roc_auc_score
from step_traffic import (  # (this folder: run as a script)
    CONTAMINATION,
    RULE,
    calibration,
    flag_rates,
    judged,
    print_grids,
)

from aisdati.ais.card import read_card
from aisdati.detectors.traffic import Traffic
from aisdati.geo import EARTH_RADIUS_M, haversine_m, initial_bearing_deg, legs_m, unit_vectors


def turns(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The wrapped change of course at each inner report of a [n, 2] lon/lat track (degrees;
    reports that did not move left out), the distance along the track there (m), and those
    reports [m, 2]."""
    moved = np.r_[True, (np.diff(positions, axis=0) != 0).any(axis=1)]
    p = positions[moved]
    if len(p) < 3:
        return np.zeros(0), np.zeros(0), np.zeros((0, 2))
    course = initial_bearing_deg(p[:-1, 0], p[:-1, 1], p[1:, 0], p[1:, 1])
    along = np.cumsum(legs_m(p))[:-1]
    return (np.diff(course) + 180.0) % 360.0 - 180.0, along, p[1:-1]


def winding_deg(positions: np.ndarray) -> float:
    """|total rotation of the heading| of a [n, 2] lon/lat track, degrees."""
    return float(abs(turns(positions)[0].sum()))


def turning_ahead(positions: np.ndarray, within_km: float) -> tuple[np.ndarray, np.ndarray]:
    """At each inner report, |rotation of the heading| over the next `within_km` of track
    (degrees), and the reports [m, 2]."""
    turn, along, points = turns(positions)
    rotated = np.r_[0.0, np.cumsum(turn)]
    ends = np.searchsorted(along, along + within_km * 1000.0, side="right")
    return np.abs(rotated[ends] - rotated[np.arange(len(turn))]), points


def local_winding_deg(positions: np.ndarray, within_km: float) -> float:
    """The largest |rotation of the heading| over a stretch of at most `within_km` of track."""
    ahead = turning_ahead(positions, within_km)[0]
    return float(ahead.max()) if len(ahead) else 0.0


class PlaceTurning:
    """How much more a track turns within `within_km` than the training traffic turned at the
    same place: per report, its `turning_ahead` less the largest of the training reports within
    `within_km` of it (0 where there is none); the track's largest excess."""

    def __init__(self, tracks: list[np.ndarray], vessels: np.ndarray, within_km: float) -> None:
        self.within_km = within_km
        profiles = [turning_ahead(t, within_km) for t in tracks]
        self.turning = np.concatenate([a for a, _ in profiles])
        self.vessel = np.repeat(vessels, [len(a) for a, _ in profiles])
        self.tree = cKDTree(unit_vectors(np.concatenate([p for _, p in profiles])))
        self.training = np.array(
            [self.excess(t, v) for t, v in zip(tracks, vessels, strict=True)]
        )  # each against the other vessels' tracks, as the traffic term is calibrated

    def excess(self, positions: np.ndarray, vessel: int = -1) -> float:
        ahead, points = turning_ahead(positions, self.within_km)
        if not len(ahead):
            return 0.0
        near = cKDTree(unit_vectors(points)).sparse_distance_matrix(
            self.tree, self.within_km * 1000.0 / EARTH_RADIUS_M, output_type="ndarray"
        )
        other = self.vessel[near["j"]] != vessel
        reference = np.zeros(len(ahead))
        np.maximum.at(reference, near["i"][other], self.turning[near["j"][other]])
        return float((ahead - reference).max())


class PathExcess:
    """A track's length less the shortest way it could have sailed along the training traffic
    between its ends: straight from its first report to a report of a training track, along that
    track either way, straight from there to its last report (the least over the training
    tracks, its own vessel's left out); metres, no parameter. `split` sums it over the track's
    two halves cut at its report farthest from its first, so a round trip is two one-way trips."""

    def __init__(self, tracks: list[np.ndarray], vessels: np.ndarray, split: bool = False) -> None:
        self.tracks = tracks
        self.vessels = vessels
        self.split = split
        self.along = [np.r_[0.0, np.cumsum(legs_m(t))] for t in tracks]
        self.training = np.array([self.excess(t, v) for t, v in zip(tracks, vessels, strict=True)])

    def shortest_m(self, start: np.ndarray, end: np.ndarray, vessel: int = -1) -> float:
        """The shortest start -> a training report -> along its track -> end (metres)."""
        best = np.inf
        for points, along, v in zip(self.tracks, self.along, self.vessels, strict=True):
            if v == vessel:
                continue
            to_start = haversine_m(start[0], start[1], points[:, 0], points[:, 1])
            to_end = haversine_m(end[0], end[1], points[:, 0], points[:, 1])
            # its way (join at a, leave at b >= a), then the other way (b <= a)
            ahead = np.minimum.accumulate(to_start - along) + along + to_end
            back = np.minimum.accumulate((to_start + along)[::-1])[::-1] - along + to_end
            best = min(best, float(ahead.min()), float(back.min()))
        return best

    def excess(self, positions: np.ndarray, vessel: int = -1) -> float:
        if not self.split:
            return self.one_way(positions, vessel)
        p = positions
        turn = int(np.argmax(haversine_m(p[0, 0], p[0, 1], p[:, 0], p[:, 1])))
        return self.one_way(p[: turn + 1], vessel) + self.one_way(p[turn:], vessel)

    def one_way(self, positions: np.ndarray, vessel: int) -> float:
        if len(positions) < 2:
            return 0.0
        length = float(legs_m(positions).sum())
        return length - self.shortest_m(positions[0], positions[-1], vessel)


def leg_speeds_mps(timed: np.ndarray) -> np.ndarray:
    """The implied speed of each leg of a [n, 3] (lon, lat, seconds) track, m/s; legs between
    reports at the same second are left out (their speed is not defined)."""
    dt = np.diff(timed[:, 2])
    ok = dt > 0
    return legs_m(timed[:, :2])[ok] / dt[ok]


def top_speed_mps(timed: np.ndarray) -> float:
    """The largest implied speed between consecutive reports, m/s."""
    speeds = leg_speeds_mps(timed)
    return float(speeds.max()) if len(speeds) else 0.0


def relative_top_speed(timed: np.ndarray) -> float:
    """The top speed over the median leg's: a fast vessel is fast all along, a position jump
    for two legs."""
    speeds = leg_speeds_mps(timed)
    return float(speeds.max() / max(np.median(speeds), 0.01)) if len(speeds) else 0.0


def speed_spike(timed: np.ndarray) -> float:
    """The largest ratio of a leg's implied speed to the faster of its neighbouring legs': a
    boat that speeds up is fast on consecutive legs, a displaced stretch on its entry and exit
    legs only."""
    speeds = leg_speeds_mps(timed)
    if len(speeds) < 2:
        return 0.0
    neighbours = np.maximum(np.r_[speeds[1], speeds[:-1]], np.r_[speeds[1:], speeds[-2]])
    return float((speeds / np.maximum(neighbours, 0.01)).max())


def self_crossings(positions: np.ndarray) -> float:
    """How many pairs of non-adjacent segments of a [n, 2] lon/lat track intersect."""
    moved = np.r_[True, (np.diff(positions, axis=0) != 0).any(axis=1)]
    p = positions[moved]
    if len(p) < 4:
        return 0.0
    segments = shapely.linestrings(np.stack([p[:-1], p[1:]], axis=1))
    a, b = shapely.STRtree(segments).query(segments, predicate="intersects")
    return float(np.count_nonzero(b > a + 1))


SIGNALS = (
    "winding", "crossings", "local", "place", "excess", "split", "speed", "relspeed", "spike",
)  # fmt: skip
TIMED = ("speed", "relspeed", "spike")
"""Signals that read each track's report times too: their tracks are [n, 3] (lon, lat, s)."""
Signal = Callable[[list[np.ndarray], np.ndarray], tuple[np.ndarray, Callable[[np.ndarray], float]]]
"""(training tracks, their vessels) -> (the training tracks' own values, the judge of a track)."""


def signal_of(name: str, within_km: float) -> Signal:
    if name == "place":

        def place(tracks: list[np.ndarray], vessels: np.ndarray):
            model = PlaceTurning(tracks, vessels, within_km)
            return model.training, model.excess

        return place
    if name in ("excess", "split"):

        def excess(tracks: list[np.ndarray], vessels: np.ndarray):
            model = PathExcess(tracks, vessels, split=name == "split")
            return model.training, model.excess

        return excess
    one = {
        "winding": winding_deg,
        "crossings": self_crossings,
        "local": lambda positions: local_winding_deg(positions, within_km),
        "speed": top_speed_mps,
        "relspeed": relative_top_speed,
        "spike": speed_spike,
    }[name]
    return lambda tracks, _: (np.array([one(t) for t in tracks]), one)


def flagged_at(values: dict[str, np.ndarray], cal: dict[str, np.ndarray], q: float) -> np.ndarray:
    """Tracks where any term passes its training quantile q."""
    return np.any([values[k] > np.quantile(cal[k], q) for k in values], axis=0)


def union_quantile(cal: dict[str, np.ndarray]) -> float:
    """The largest common quantile q at which the union flags at most `CONTAMINATION` of the
    training tracks themselves (bisection)."""
    lo, hi = 1.0 - CONTAMINATION, 1.0
    for _ in range(40):
        mid = (lo + hi) / 2
        if flagged_at(cal, cal, mid).mean() > CONTAMINATION:
            lo = mid
        else:
            hi = mid
    return hi


def cell_result(cell: Path, signal: Signal, timed: bool) -> dict[str, float]:
    step, lane, models = judged(cell)
    read = ["track_id", "lon", "lat", "time"] if timed else ["track_id", "lon", "lat"]
    points = pd.read_parquet(cell / "data" / "points.parquet", columns=read)
    columns = ["lon", "lat"]
    if timed:
        points["s"] = (points["time"] - points["time"].min()).dt.total_seconds()
        columns.append("s")
    by_track = {t: g[columns].to_numpy() for t, g in points.groupby("track_id", sort=False)}
    stem = models / "all-nearest"
    card = read_card(stem.with_suffix(".json"))
    kept = Traffic.read(stem.with_suffix(".npz"), card)
    own = [by_track[t] for t in card.data.track_ids] if timed else kept.tracks
    training, judge = signal(own, kept.mmsi)
    cal = {
        "step": calibration(models / "all.json", "step"),
        "lane": calibration(stem.with_suffix(".json"), "lane"),
        "third": training,
    }
    values = {
        "step": step.value.to_numpy(),
        "lane": lane.value.to_numpy(),
        "third": np.array([judge(by_track[t]) for t in step.index]),
    }
    ashore = RULE.flags(step.ashore_reports.to_numpy())
    label = step.label.to_numpy()
    counts, lengths = step.ashore_reports.to_numpy(), step.n_points.to_numpy()
    q = union_quantile(cal)
    two = {k: values[k] for k in ("step", "lane")}
    flags = {
        "either2": flagged_at(two, cal, 1 - CONTAMINATION) | ashore,
        "either3": flagged_at(values, cal, q) | ashore,
        "alone": (values["third"] > np.quantile(cal["third"], 1 - CONTAMINATION)) | ashore,
    }
    return {
        "third": roc_auc_score(label, RULE.ranked(values["third"], counts, lengths)),
        "q": q,
        "third q95": np.quantile(cal["third"], 1 - CONTAMINATION),
    } | flag_rates(flags, label, step.kind.to_numpy())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("grids", type=Path, nargs="+", help="grid folders (<out>/<area>/<tier>)")
    parser.add_argument("--signal", choices=SIGNALS, default="winding")
    parser.add_argument(
        "--within", type=float, default=5.0, help="km, for --signal local and place"
    )
    args = parser.parse_args()
    signal = signal_of(args.signal, args.within)
    figures = {
        f"{args.signal} AUC": ("third", ".3f"),
        "training q95 of it": ("third q95", ".1f"),
        "q of either3": ("q", ".3f"),
    }
    print_grids(
        args.grids,
        lambda cell: cell_result(cell, signal, args.signal in TIMED),
        figures,
        ("alone", "either2", "either3"),
        ("either2", "either3"),
    )


if __name__ == "__main__":
    main()
