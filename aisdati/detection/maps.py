"""The maps of `aisdati detect`: map.png, map.html and evidence/track-<id>.png.

map.png draws the test tracks over the offline coastline, the flagged ones in red with what they
were compared with; map.html is the same as a zoomable page that works offline
(`aisdati.detection.webmap`); each evidence figure shows one
flagged track, what it was compared with and its deviation profile, to say why it stands out."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib.dates as mdates
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from aisdati.detection.webmap import html_detection_map
from aisdati.events.kinds import ACTIVITY, ALERT, KINDS
from aisdati.events.stretch import deviation_stretch
from aisdati.events.table import events_geojson
from aisdati.execution import InProcess, Runner
from aisdati.outdir import atomic_write_bytes
from aisdati.plots import draw_land, drawn, plain_text, set_map_limits

if TYPE_CHECKING:
    from aisdati.detection.run import Detection

EVIDENCE_FIGURES = 20
"""At most this many flagged tracks (the highest ranked) get an evidence figure."""
GAP_LABELS = 12
"""map.png labels the longest this many gaps with their duration (a month of a busy area holds
hundreds: their labels would hide the map); map.html labels every one."""
MAP_UNFLAGGED_TRACKS = 5_000
"""At most this many unflagged tracks are drawn on map.png and map.html (evenly: every k-th in
the scores' order); flagged tracks are always drawn, all of them. A month of a coast holds
hundreds of thousands of tracks: all of them would make the page gigabytes and the PNG
minutes, and the grey context reads the same from a few thousand."""


def map_subset(flagged: np.ndarray, most: int) -> np.ndarray:
    """Indices of the tracks the maps draw: every flagged one, and of the unflagged ones all,
    or every k-th when there are more than `most`."""
    normal = np.flatnonzero(~flagged)
    stride = -(-len(normal) // most) if len(normal) > most else 1
    return np.sort(np.r_[np.flatnonzero(flagged), normal[::stride]])


@dataclass(frozen=True)
class AlertMark:
    """The alert an evidence figure marks: its kind and stretch, from when to when (UTC)."""

    kind: str
    start: pd.Timestamp
    end: pd.Timestamp
    strength: float

    @property
    def when(self) -> str:
        """'2018-08-19 06:21 to 08:58 UTC' (the end's date too where it is another day)."""
        end = (
            f"{self.end:%H:%M}"
            if self.end.date() == self.start.date()
            else f"{self.end:%Y-%m-%d %H:%M}"
        )
        return f"{self.start:%Y-%m-%d %H:%M} to {end} UTC"


def strongest_alert(events: pd.DataFrame, track_id: int) -> AlertMark | None:
    """The track's strongest alert (None: it raised none)."""
    if not len(events):
        return None
    mine = events[(events["class"] == ALERT) & (events["track_id"] == track_id)]
    if not len(mine):
        return None
    e = mine.loc[mine["strength"].idxmax()]
    return AlertMark(
        str(e["kind"]), pd.Timestamp(e["start"]), pd.Timestamp(e["end"]), float(e["strength"])
    )


def gap_links(events: pd.DataFrame) -> list[tuple[np.ndarray, str]]:
    """Each gap's link ([2, 2] lon/lat: the last report before it, the first after) and its
    duration as the map labels it, longest first."""
    if not len(events):
        return []
    gaps = events[events["kind"] == "gap"].sort_values("duration_s", ascending=False)
    return [
        (np.column_stack([lons, lats])[[0, -1]].astype(float), duration_text(seconds))
        for lons, lats, seconds in zip(gaps["lons"], gaps["lats"], gaps["duration_s"], strict=True)
    ]


def area_outlines(events: pd.DataFrame) -> list[np.ndarray]:
    """Each area event's outline ([k, 2] lon/lat, a closed ring: `EventKind.area`)."""
    if not len(events):
        return []
    areas = events[events["kind"].map(lambda k: KINDS[k].area)]
    return [
        np.column_stack([a, b]).astype(float)
        for a, b in zip(areas["lons"], areas["lats"], strict=True)
    ]


def meetings(events: pd.DataFrame) -> list[tuple[list[np.ndarray], str]]:
    """Each event of several vessels that is not an area (an encounter: its vessels' stretches,
    NaN between them, `aisdati.events.record.EVENT_COLUMNS`): each stretch ([k, 2] lon/lat)
    and the MMSIs it names, as map.png draws and labels it rather than one point."""
    if not len(events):
        return []
    out = []
    for e in events[_several(events)].itertuples():
        xy = np.column_stack([e.lons, e.lats]).astype(float)
        parts = np.split(xy, np.flatnonzero(np.isnan(xy[:, 0])))
        parts = [p[~np.isnan(p[:, 0])] for p in parts]
        others = json.loads(e.others) if isinstance(e.others, str) else []
        names = " / ".join(str(m) for m in [int(e.mmsi), *(int(o["mmsi"]) for o in others)])
        out.append(([p for p in parts if len(p)], f"{e.kind} {names}"))
    return out


def _several(events: pd.DataFrame) -> np.ndarray:
    """Which events hold several vessels' stretches (NaN-separated), not an area's outline."""
    parted = events["lons"].map(lambda x: bool(np.isnan(np.asarray(x, float)).any()))
    return (parted & ~events["kind"].map(lambda k: KINDS[k].area)).to_numpy(bool)


def duration_text(seconds: float) -> str:
    """'45 s', '111 min', '19.7 h': a duration as a map labels it."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min" if seconds < 7200 else f"{seconds / 3600:.1f} h"


def places(events: pd.DataFrame, cls: str) -> np.ndarray:
    """[k, 2] lon/lat where each event of class `cls` is strongest (not the `meetings`: their
    vessels' stretches are drawn)."""
    if not len(events):
        return np.empty((0, 2))
    mine = (events["class"] == cls).to_numpy(bool) & ~_several(events)
    return events.loc[mine, ["lon", "lat"]].to_numpy(np.float64)


# ------------------------------------------------------------------------------- map.png
@plain_text()  # its texts may hold model names: drawn as they are
def plot_detection_map(
    tracks: Sequence[np.ndarray],
    rollouts: Sequence[np.ndarray],
    flagged: np.ndarray,
    max_dev: np.ndarray,
    regions: Sequence[tuple[np.ndarray, np.ndarray]],
    title: str = "",
    evidence_label: str = "nearest rollout",
    events: np.ndarray | None = None,
    activity: np.ndarray | None = None,
    gaps: Sequence[tuple[np.ndarray, str]] = (),
    areas: Sequence[np.ndarray] = (),
    met: Sequence[tuple[list[np.ndarray], str]] = (),
) -> bytes:
    """map.png (its bytes): test tracks grey, flagged tracks red with their nearest rollout blue
    and a cross where they deviate most, alerts (`events`: [k, 2] lon/lat, where each is
    strongest) as orange diamonds, activity (loitering, gaps) as open blue circles, the models'
    regions dashed, each gap (`gaps`: its [2, 2] link from the last report before it to the first
    after, and its duration, longest first) a dotted blue link, the `GAP_LABELS` longest labelled
    with their duration, each area event (`areas`: its outline, e.g. an interference) an orange
    area, each meeting of vessels (`met`: each vessel's stretch and the MMSIs named) its
    stretches in purple, labelled with the vessels, over the offline
    coastline
    (aisdati.coastline, cut to the map's box at any scale; lon/lat, the longitude axis
    stretched by 1/cos(latitude) so that shapes are true)."""
    from matplotlib.collections import LineCollection

    fig, ax = plt.subplots(figsize=(9, 7.5))
    normal = [xy for xy, f in zip(tracks, flagged, strict=True) if not f]
    # one artist for all: fast for thousands of tracks
    ax.add_collection(LineCollection(normal, colors="0.55", linewidths=0.6, alpha=0.7, zorder=1))
    for xy, roll, f in zip(tracks, rollouts, flagged, strict=True):
        if f:
            ax.plot(roll[:, 0], roll[:, 1], color="tab:blue", lw=1.0, zorder=2)
            ax.plot(xy[:, 0], xy[:, 1], color="tab:red", lw=1.4, zorder=3)
            ax.plot(*xy[0], "o", color="tab:red", ms=3, zorder=3)
    if flagged.any():
        ax.plot(max_dev[flagged, 0], max_dev[flagged, 1], "kx", ms=7, mew=1.6, zorder=4)
    places = np.empty((0, 2)) if events is None else np.reshape(events, (-1, 2))
    ax.plot(places[:, 0], places[:, 1], "D", color="tab:orange", mec="k", ms=6, zorder=5)
    done = np.empty((0, 2)) if activity is None else np.reshape(activity, (-1, 2))
    ax.plot(done[:, 0], done[:, 1], "o", mfc="none", mec="tab:blue", mew=1.5, ms=7, zorder=5)
    for ring in areas:
        ax.fill(ring[:, 0], ring[:, 1], color="tab:orange", alpha=0.25, ec="tab:orange", zorder=4)
    for link, _ in gaps:
        ax.plot(link[:, 0], link[:, 1], ":", color="tab:blue", lw=1.6, zorder=4)
    _draw_meetings(ax, met)
    for link, duration in gaps[:GAP_LABELS]:
        ax.annotate(
            duration, link.mean(axis=0), fontsize=7, color="tab:blue", ha="center",
            va="bottom", zorder=6,
        )  # fmt: skip
    for lo, hi in regions:
        ax.plot(
            [lo[0], hi[0], hi[0], lo[0], lo[0]],
            [lo[1], lo[1], hi[1], hi[1], lo[1]],
            "k--",
            lw=0.8,
            zorder=1,
        )
    allpts = np.concatenate([*tracks, *[np.stack([lo, hi]) for lo, hi in regions]])
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    pad = np.maximum((hi - lo) * 0.04, 0.01)
    set_map_limits(ax, lo - pad, hi + pad)
    draw_land(ax)
    handles = _legend(evidence_label, bool(len(areas)), bool(len(met)))
    ax.legend(handles=handles, fontsize=8, loc="best")
    ax.set_title(title or "DATI anomalies")
    return drawn(fig)


def _legend(evidence_label: str, areas: bool, met: bool) -> list:
    """map.png's legend: what every map shows, and area events and meetings where it has any."""
    return [
        plt.Line2D([], [], color="0.55", lw=1, label="test track"),
        plt.Line2D([], [], color="tab:red", lw=1.4, label="flagged track"),
        plt.Line2D([], [], color="tab:blue", lw=1, label=evidence_label),
        plt.Line2D([], [], color="k", marker="x", ls="", label="largest deviation"),
        plt.Line2D([], [], color="tab:orange", mec="k", marker="D", ls="", label="alert"),
        plt.Line2D([], [], mfc="none", mec="tab:blue", marker="o", ls="", label="activity"),
        plt.Line2D([], [], color="tab:blue", ls=":", lw=1.6, label="gap (its duration)"),
        *(
            [plt.Rectangle((0, 0), 1, 1, color="tab:orange", alpha=0.25, label="area event")]
            if areas
            else []
        ),
        *(
            [plt.Line2D([], [], color="tab:purple", lw=2.2, label="meeting: each vessel")]
            if met
            else []
        ),
        plt.Line2D([], [], color="k", ls="--", lw=0.8, label="model region"),
    ]


def _draw_meetings(ax: plt.Axes, met: Sequence[tuple[list[np.ndarray], str]]) -> None:
    """Each meeting (`meetings`) as its vessels' stretches in purple, labelled with the MMSIs."""
    for parts, label in met:
        for xy in parts:
            ax.plot(xy[:, 0], xy[:, 1], "-", color="tab:purple", lw=2.2, zorder=5)
            ax.plot(*xy[-1], "o", color="tab:purple", ms=4, zorder=5)
        ax.annotate(label, parts[0][len(parts[0]) // 2], fontsize=7, color="tab:purple",
                    ha="left", va="bottom", zorder=6)  # fmt: skip


# ------------------------------------------------------------------------------ map.html
def _widen(lo: np.ndarray, hi: np.ndarray, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Grow a lon/lat box about its centre to a width / height ratio (in true distance)."""
    coslat = np.cos(np.radians((lo[1] + hi[1]) / 2))
    w, h = (hi[0] - lo[0]) * coslat, hi[1] - lo[1]
    w, h = max(w, h * ratio), max(h, w / ratio)
    mid = (lo + hi) / 2
    half = np.array([w / coslat, h]) / 2
    return mid - half, mid + half


@plain_text()  # its texts may hold model names: drawn as they are
def plot_track_evidence(
    track: np.ndarray,
    rollout: np.ndarray | None,
    profile: np.ndarray,
    stretch: tuple[int, int] | None,
    title: str,
    *,
    hours: np.ndarray | None = None,
    profile_label: str = "deviation from the rollout (m)",
    pad_frac: float = 0.15,
    pad_deg: float = 0.01,
    context: Sequence[np.ndarray] = (),
    evidence_label: str = "rollout",
    start: pd.Timestamp | None = None,
    alert: AlertMark | None = None,
) -> bytes:
    """Why one track stands out, and when, in two panels (a PNG's bytes).

    Left, a map: the coastline (at the map's scale), other tracks for context (`context`, light
    grey), the track (black, a green dot at its start), its rollout (blue dashed, when given),
    the stretch `track[i0:i1]` in red and a cross at the point of largest `profile`. The box is
    the track's and rollout's, padded by `pad_frac` of its span and at least `pad_deg` degrees.
    Right: `profile` ([n] metres, one value per track point: e.g. distance to the matched
    rollout point, a teacher-forced step error) against the point index, or against `hours`
    ([n] hours since the start) when given, with the stretch shaded: against the time of day
    (UTC) when the track's `start` is given too. `alert` (the track's strongest,
    `strongest_alert`) is drawn orange on both panels, from when to when.

    `stretch` is a Python slice (i0, i1): points i0..i1-1."""
    track = np.asarray(track, dtype=float)
    profile = np.asarray(profile, dtype=float)
    n = len(track)
    if track.ndim != 2 or track.shape[1] != 2 or n == 0:
        raise ValueError(f"track must be [n, 2] lon/lat, got shape {track.shape}")
    if profile.shape != (n,):
        raise ValueError(f"profile must have one value per track point ({n}), got {profile.shape}")
    x = np.arange(n) if hours is None else np.asarray(hours, dtype=float)
    if x.shape != (n,):
        raise ValueError(f"hours must have one value per track point ({n}), got {x.shape}")
    if stretch is not None:
        i0, i1 = max(0, int(stretch[0])), min(n, int(stretch[1]))
        stretch = (i0, i1) if i1 > i0 else None
    peak = int(np.nanargmax(profile)) if np.isfinite(profile).any() else None
    times = None
    if start is not None and hours is not None:
        # to the second: hours summed in floats put a report at 06:19:59.9999, before its alert
        times = (pd.Timestamp(start) + pd.to_timedelta(x, unit="h")).tz_convert("UTC").round("s")
    marked = alert_points(times, alert)

    fig, (ax, axp) = plt.subplots(1, 2, figsize=(13, 5.6), gridspec_kw={"width_ratios": [1.15, 1]})
    pts = [track] + ([np.asarray(rollout, dtype=float)] if rollout is not None else [])
    allpts = np.concatenate(pts)
    allpts = allpts[np.isfinite(allpts).all(axis=1)]
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    pad = np.maximum((hi - lo) * pad_frac, pad_deg)
    lo, hi = _widen(lo - pad, hi + pad, ratio=1.25)
    _evidence_map(ax, track, rollout, profile, stretch, peak, context, evidence_label)
    if marked is not None and alert is not None and times is not None:
        _alert_on_map(ax, track, times, marked, alert)
    set_map_limits(ax, lo, hi)
    draw_land(ax)
    ax.legend(fontsize=8, loc="best")
    when = None if times is None else times.tz_localize(None).to_numpy()
    _profile_panel(
        axp, x if when is None else when, profile, stretch, peak, profile_label, hours is None
    )
    if marked is not None and alert is not None and when is not None:
        axp.axvspan(
            when[marked[0]], when[marked[1] - 1], color="tab:orange", alpha=0.3,
            label=f"{alert.kind}: {alert.when}",
        )  # fmt: skip
        axp.legend(fontsize=8, loc="best")
    if times is not None:
        title += f"\n{times[0]:%Y-%m-%d %H:%M} to {times[-1]:%Y-%m-%d %H:%M} UTC"
    fig.suptitle(title)
    return drawn(fig)


def alert_points(times: pd.DatetimeIndex | None, alert: AlertMark | None) -> tuple[int, int] | None:
    """The points (a slice i0, i1) of the alert's stretch: those from its start to its end, or,
    where none falls inside (a gap between two reports), the two about it."""
    if times is None or alert is None or not len(times):
        return None
    inside = np.flatnonzero((times >= alert.start) & (times <= alert.end))
    if len(inside):
        return int(inside[0]), int(inside[-1]) + 1
    after = int(np.clip(np.searchsorted(times, alert.start), 1, len(times) - 1))
    return after - 1, after + 1


def _alert_on_map(
    ax: plt.Axes,
    track: np.ndarray,
    times: pd.DatetimeIndex,
    marked: tuple[int, int],
    alert: AlertMark,
) -> None:
    """The alert's stretch on the evidence map, orange, its ends labelled with their times."""
    i0, i1 = marked
    seg = track[i0 : max(i1, i0 + 2)]
    ax.plot(
        seg[:, 0], seg[:, 1], color="tab:orange", lw=5, alpha=0.85, zorder=3.5,
        label=f"strongest alert, {alert.kind}: {alert.when}",
    )  # fmt: skip
    ends = {i0: (6, 6), min(i1, len(track)) - 1: (6, -14)}  # the end below: a track comes back
    for k, offset in ends.items():
        ax.annotate(
            f"{times[k]:%H:%M}", track[k], xytext=offset, textcoords="offset points",
            fontsize=8, color="tab:orange", fontweight="bold", zorder=7,
        )  # fmt: skip


def _evidence_map(
    ax: plt.Axes,
    track: np.ndarray,
    rollout: np.ndarray | None,
    profile: np.ndarray,
    stretch: tuple[int, int] | None,
    peak: int | None,
    context: Sequence[np.ndarray],
    evidence_label: str,
) -> None:
    """The lines of the evidence figure's map panel (see `plot_track_evidence`)."""
    for xy in context:
        ax.plot(xy[:, 0], xy[:, 1], color="0.7", lw=0.6, alpha=0.8, zorder=1)
    if rollout is not None:
        ax.plot(
            rollout[:, 0],
            rollout[:, 1],
            "--",
            color="tab:blue",
            lw=1.3,
            zorder=2,
            label=evidence_label,
        )
    ax.plot(track[:, 0], track[:, 1], color="black", lw=1.4, zorder=3, label="track")
    ax.plot(*track[0], "o", color="tab:green", ms=7, mec="black", zorder=5, label="start")
    if stretch is not None:
        seg = track[stretch[0] : max(stretch[1], stretch[0] + 2)]
        ax.plot(
            seg[:, 0],
            seg[:, 1],
            color="tab:red",
            lw=3,
            zorder=4,
            label="largest deviation's stretch",
        )
    if peak is not None:
        ax.plot(
            *track[peak],
            "x",
            color="tab:red",
            ms=10,
            mew=2.2,
            zorder=6,
            label=f"max {profile[peak]:,.0f} m",
        )


def _profile_panel(
    axp: plt.Axes,
    x: np.ndarray,
    profile: np.ndarray,
    stretch: tuple[int, int] | None,
    peak: int | None,
    profile_label: str,
    by_index: bool,
) -> None:
    """The evidence figure's deviation profile over time: against the point index (`by_index`),
    hours, or times (`x` of datetime64)."""
    axp.plot(x, profile, color="black", lw=1.2)
    if stretch is not None:
        axp.axvspan(
            x[stretch[0]],
            x[stretch[1] - 1],
            color="tab:red",
            alpha=0.18,
            label=f"largest deviation's stretch [{stretch[0]}, {stretch[1]})",
        )
    if peak is not None:
        axp.plot(x[peak], profile[peak], "x", color="tab:red", ms=10, mew=2.2)
    dated = np.issubdtype(x.dtype, np.datetime64)
    axp.set_xlabel(
        "time (UTC)" if dated else "point index" if by_index else "hours since the start"
    )
    axp.set_ylabel(profile_label)
    if dated:  # dates and times, none over another
        locator = mdates.AutoDateLocator(maxticks=7)
        axp.xaxis.set_major_locator(locator)
        axp.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    else:
        span = float(x[-1] - x[0]) or 1.0
        axp.set_xlim(x[0] - 0.015 * span, x[-1] + 0.015 * span)
    axp.set_ylim(bottom=min(0.0, float(np.nanmin(profile))) if peak is not None else 0.0)
    axp.grid(alpha=0.3)
    if stretch is not None:
        axp.legend(fontsize=8, loc="best")


# ------------------------------------------------------------------ a detection's maps
FigureJob = tuple[Callable[..., bytes], tuple, dict[str, Any]]
"""A figure to draw: (function returning its PNG, positional arguments, keyword arguments)."""


def figure_png(figure: FigureJob) -> bytes:
    """One drawing task of `write_maps`: the figure's PNG."""
    draw, args, kwargs = figure
    return draw(*args, **kwargs)


def write_maps(result: Detection, out: Path, runner: Runner | None = None) -> list[Path]:
    """map.png, map.html and the evidence figures of a detection, in `out`. The PNGs are drawn
    as tasks of `runner` (default: here), which hand back their bytes: on a cluster the
    figures are drawn side by side, and only this process writes the outputs."""
    flagged = result.scores["flagged"].to_numpy()
    stretches = [deviation_stretch(p) for p in result.profiles]
    title = _map_title(result)
    regions = [m.card.region.bounds for m in result.models]
    drawn = map_subset(flagged, MAP_UNFLAGGED_TRACKS)
    shown = flagged[drawn]
    if len(drawn) < len(flagged):
        title += f"; {int((~shown).sum()):,} of {int((~flagged).sum()):,} others drawn"
    tracks = [result.tracks[i].positions for i in drawn]
    rollouts = [result.rollouts[i] for i in drawn]
    rows = result.scores.iloc[drawn]
    max_dev = rows[["max_dev_lon", "max_dev_lat"]].to_numpy()
    evidence = out / "evidence"
    figures: list[tuple[Path, FigureJob]] = [
        (
            out / "map.png",
            (
                plot_detection_map,
                (tracks, rollouts, shown, max_dev, regions),
                {
                    "title": title,
                    "evidence_label": result.evidence_kind,
                    "events": places(result.events, ALERT),
                    "activity": places(result.events, ACTIVITY),
                    "gaps": gap_links(result.events),
                    "areas": area_outlines(result.events),
                    "met": meetings(result.events),
                },
            ),
        ),
        *evidence_figures(result, evidence, stretches),
    ]
    # map.png draws the test tracks (at 700 tracks, eight evidence figures' time): started
    # first on a cluster, it does not end last
    costs = [float(len(figures)), *([1.0] * (len(figures) - 1))]
    pngs = (runner or InProcess()).map(figure_png, [job for _, job in figures], costs=costs)
    page = out / "map.html"
    html_detection_map(
        tracks,
        rollouts,
        [_track_props(r) for r in rows.itertuples()],
        shown,
        regions,
        page,
        stretches=[
            (f"track {t.track_id}", t.positions[a:b])
            for t, (a, b), f in zip(result.tracks, stretches, flagged, strict=True)
            if f
        ],
        events=events_geojson(result.events),
        title=title,
    )
    if len(figures) > 1:
        evidence.mkdir(parents=True, exist_ok=True)
    for (path, _), png in zip(figures, pngs, strict=True):
        atomic_write_bytes(path, png)
    paths = [path for path, _ in figures]
    return [paths[0], page, *paths[1:]]


def evidence_figures(
    result: Detection, folder: Path, stretches: list[tuple[int, int]]
) -> list[tuple[Path, FigureJob]]:
    """evidence/track-<id>.png for the highest-ranked flagged tracks, to draw: the track, what
    it was compared with, the stretch of largest deviation, its strongest alert from when to
    when, and the deviation profile over time."""
    rows = result.scores[result.scores["flagged"]].sort_values("rank").head(EVIDENCE_FIGURES)
    index = {t.track_id: i for i, t in enumerate(result.tracks)}
    figures = []
    for row in rows.itertuples():
        i = index[int(row.track_id)]
        track = result.tracks[i]
        title = (
            f"rank {int(row.rank)}: track {int(row.track_id)} (MMSI {int(row.mmsi)}), "
            f"score {result.judged_by.text(row.score)}, model {row.model}"
        )
        args = (track.positions, result.rollouts[i], result.profiles[i], stretches[i], title)
        kwargs = {
            "hours": np.r_[0.0, np.cumsum(track.dts)],
            "profile_label": result.profile_kind,
            "evidence_label": result.evidence_kind,
            "start": track.start,
            "alert": strongest_alert(result.events, int(row.track_id)),
        }
        path = folder / f"track-{int(row.track_id)}.png"
        figures.append((path, (plot_track_evidence, args, kwargs)))
    return figures


def _track_props(row: Any) -> dict[str, Any]:
    return {
        "track_id": int(row.track_id),
        "mmsi": int(row.mmsi),
        "rank": int(row.rank),
        "score": round(float(row.score), 4),
        "threshold": round(float(row.threshold), 4),
        "max_dev_m": round(float(row.max_dev_m), 1),
        "max_dev_lon": float(row.max_dev_lon),
        "max_dev_lat": float(row.max_dev_lat),
        "judged by": str(row.model),
    }


def _map_title(result: Detection) -> str:
    """What the maps show: the method and score, and how many tracks were flagged by what rule."""
    s = result.settings
    n, f = len(result.scores), int(result.scores["flagged"].sum())
    rule = f"calibrated, contamination {s.contamination:g}" if s else "calibrated"
    if s and s.rule == "top":
        rule = f"top {s.top_percent:g}% of the batch"
    elif s and s.rule == "relative":
        rule = f"the paper's rule: score > {s.threshold:g} x the batch's largest"
    what = f"{s.method} ({s.score})" if s else "DATI"
    return f"{what} anomalies: {f} of {n} test tracks flagged ({rule})"
