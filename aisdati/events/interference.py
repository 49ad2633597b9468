"""GNSS interference over an area (`aisdati.events.kinds`: gnss-interference): many vessels
displaced at once, the same way, in one area, as one event with its area, time span and vessels.

Jamming and spoofing of satellite positioning (the Baltic and the Black Sea since 2022, C4ADS'
"Above Us Only Stars" before them) move every receiver of an area at once: vessels' positions
jump by kilometres together, onto one common point (an airport), onto a circle around one, or
ashore. Each vessel's jumps are read with the one-vessel machinery (`aisdati.events.motion`: a
step's displacement that its reported motion does not explain) at a floor of their own
(`EventSettings.interference_min_m`, under a position jump's alert and over a turn's or a
receiver clock's share); vessels whose jumps fall within minutes of one another and within an
area's reach of one another are one candidate area (`areas`); and the candidate becomes an
event where at least `interference_min_vessels` of them were displaced *alike*
(`signature`): by one common shift, onto (or from) one common point, onto one circle, or onto
land. Jumps that share nothing (a few vessels' own glitches at a busy hour) raise nothing. The
events of one interference (its start and its end, hours apart) are merged by the vessels they
share. Their vessels' own position jumps and reports ashore are folded into it
(`aisdati.events.fleet.folded`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely

from aisdati.events.behaviour import land_mask
from aisdati.events.motion import JUMP_MAX_S, jump_sizes, unexplained_m
from aisdati.events.record import event_row
from aisdati.events.reports import M_PER_DEG
from aisdati.events.settings import EventSettings
from aisdati.geo import haversine_m

if TYPE_CHECKING:
    from aisdati.events.fleet import Fleet
    from aisdati.events.rules import EventRules

OUTLINE_M = 1000.0
"""The area's outline: the convex hull of its displaced vessels' jumps (from and to), this much
wider (one vessel's jumps still outline an area)."""
MIN_ARC_DEG = 90.0
"""Positions on a circle cover at least this much of it (a bend of a lane fits a circle too)."""


@dataclass(frozen=True)
class Jumps:
    """Every vessel's jumps at the interference floor, one row each (arrays of equal length):
    the step from report `before` to report `after` of vessel `mmsi`."""

    mmsi: np.ndarray
    t0: np.ndarray
    """When the vessel was last where it was (the report before the jump), seconds."""
    t1: np.ndarray
    """When it was first where it jumped to, seconds."""
    before: np.ndarray
    """[n, 2] lon/lat before the jump."""
    after: np.ndarray
    """[n, 2] lon/lat after it."""
    shift: np.ndarray
    """[n, 2] east/north metres of the jump its reported motion does not explain."""
    metres: np.ndarray

    def __len__(self) -> int:
        return len(self.mmsi)


def fleet_jumps(fleet: Fleet, s: EventSettings) -> Jumps:
    """Every vessel's steps whose unexplained displacement reaches the interference floor and
    stands out of that vessel's own (over its scale, `jump_sizes`: `interference_z`), within a
    jump's longest step; an MMSI's two transmitters heard as one (`Fleet.as_heard`); the floor
    looked for in all vessels' steps at once, the scale only in the vessels that reach it."""
    fleet = fleet.as_heard
    every = fleet.joined  # (a vessel with no step that far unexplained has no jump)
    far = (unexplained_m(every.reports, s) >= s.interference_min_m) & (
        every.reports.dt_s <= s.jump_step_max_s
    )
    may = every.any_step(far) & (np.diff(every.bounds) >= 3)
    parts = []
    for v in (v for k, v in enumerate(fleet.vessels.values()) if may[k]):
        metres = unexplained_m(v, s)
        k = np.flatnonzero((metres >= s.interference_min_m) & (v.dt_s <= s.jump_step_max_s))
        if k.size == 0:
            continue
        k = k[jump_sizes(v, s)[k] > s.interference_z]
        parts.append(
            (np.full(k.size, v.mmsi), v.time_s[k], v.time_s[k + 1], v.positions(k),
             v.positions(k + 1), v.residual[k], metres[k])
        )  # fmt: skip
    if not parts:
        return Jumps(np.zeros(0, np.int64), *[np.zeros(0)] * 2, *[np.zeros((0, 2))] * 3,
                     np.zeros(0))  # fmt: skip
    joined = [np.concatenate(p) for p in zip(*parts, strict=True)]
    order = np.argsort(joined[2], kind="stable")
    return Jumps(*(a[order] for a in joined))


def areas(j: Jumps, s: EventSettings) -> list[np.ndarray]:
    """The jumps (sorted by `t1`) of vessels displaced at once in one area: linked when of
    different vessels, within `interference_within_s` of one another, and within
    `interference_radius_m` of one another before or after their jumps; each group of
    `interference_min_vessels` vessels or more, as indices."""
    parent = np.arange(len(j))

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return int(a)

    for a in range(len(j)):
        b = a + 1 + np.flatnonzero(j.t1[a + 1 :] - j.t1[a] <= s.interference_within_s)
        if b.size == 0:
            continue
        near = np.minimum(
            haversine_m(*j.before[a], j.before[b, 0], j.before[b, 1]),
            haversine_m(*j.after[a], j.after[b, 0], j.after[b, 1]),
        )
        for c in b[(near <= s.interference_radius_m) & (j.mmsi[b] != j.mmsi[a])]:
            parent[root(a)] = root(int(c))
    roots = np.array([root(a) for a in range(len(j))], dtype=np.int64)
    groups = [np.flatnonzero(roots == r) for r in np.unique(roots)]
    return [g for g in groups if len(np.unique(j.mmsi[g])) >= s.interference_min_vessels]


@dataclass(frozen=True)
class Signature:
    """What the displaced vessels of an area share: how (`how`, in words), and which jumps."""

    how: str
    jumps: np.ndarray


def signature(
    j: Jumps, group: np.ndarray, s: EventSettings, land: np.ndarray | None
) -> Signature | None:
    """The ways a candidate area's vessels were displaced alike, each by at least
    `interference_min_vessels` of them (most first; the jumps of all): one common shift, onto
    or from one common point, onto one circle, or ashore (`land`: which of the group's jumps
    end on land, `land_mask`, asked of the group's area alone); None where they share none."""
    found = [
        _common_shift(j, group, s), _common_point(j, group, s), _circle(j, group, s),
        _ashore(group, land),
    ]  # fmt: skip
    alike = [
        f for f in found if f is not None and _vessels(j, f.jumps) >= s.interference_min_vessels
    ]
    if not alike:
        return None
    alike.sort(key=lambda f: -_vessels(j, f.jumps))
    how = "; ".join(f.how for f in alike)
    return Signature(how, np.unique(np.concatenate([f.jumps for f in alike])))


def _common_shift(j: Jumps, group: np.ndarray, s: EventSettings) -> Signature | None:
    """The largest set of jumps that each differ from one (the seed) or from its reverse (the
    jump back) by at most `interference_shift_share` of the larger: the vessels moved by one
    vector, and back."""
    shift, size = j.shift[group], j.metres[group]
    best = None
    for seed in range(len(group)):
        apart = np.minimum(np.hypot(*(shift - shift[seed]).T), np.hypot(*(shift + shift[seed]).T))
        larger = np.maximum(size, size[seed])
        tol = np.maximum(s.interference_point_m, s.interference_shift_share * larger)
        members = group[apart <= tol]
        if best is None or _vessels(j, members) > _vessels(j, best):
            best = members
    if best is None:
        return None
    mean = j.shift[best[np.argmax(j.metres[best])]]
    bearing = float(np.degrees(np.arctan2(mean[0], mean[1])) % 360.0)
    said = f"shifted {np.median(j.metres[best]) / 1000:.1f} km towards {bearing:.0f} deg (or back)"
    return Signature(said, best)


def _common_point(j: Jumps, group: np.ndarray, s: EventSettings) -> Signature | None:
    """The largest set of jumps that land on or leave one point: within
    `interference_point_m` of a seed's end."""
    best, at = None, None
    for xy in np.concatenate([j.after[group], j.before[group]]):
        close = np.minimum(
            haversine_m(*xy, j.after[group, 0], j.after[group, 1]),
            haversine_m(*xy, j.before[group, 0], j.before[group, 1]),
        )
        members = group[close <= s.interference_point_m]
        if best is None or _vessels(j, members) > _vessels(j, best):
            best, at = members, xy
    if best is None or at is None:
        return None
    return Signature(f"onto one point ({at[1]:.4f}, {at[0]:.4f})", best)


def _vessels(j: Jumps, rows: np.ndarray) -> int:
    return len(np.unique(j.mmsi[rows]))


def _circle(j: Jumps, group: np.ndarray, s: EventSettings) -> Signature | None:
    """The jumps whose displaced ends lie on one circle (least squares, refitted on the
    nearest twice), its radius under the area's reach, covering at least `MIN_ARC_DEG` of it."""
    if len(group) < s.interference_min_vessels:
        return None
    rows, ends = displaced_ends(j, group)
    xy, origin = _metres(ends)
    keep = np.ones(len(xy), bool)
    for _ in range(3):
        if keep.sum() < 3:
            return None
        centre, radius = _fit_circle(xy[keep])
        off = np.abs(np.hypot(*(xy - centre).T) - radius)
        keep = off <= max(s.interference_point_m, 2 * s.interference_circle_share * radius)
    on = off <= max(s.interference_point_m / 3, s.interference_circle_share * radius)
    if _vessels(j, rows[on]) <= s.interference_min_vessels:  # any three places are on a circle
        return None
    if on.sum() < s.interference_min_vessels + 2 or not 0 < radius <= s.interference_radius_m:
        return None
    angles = np.sort(np.degrees(np.arctan2(*(xy[on] - centre).T[::-1])) % 360.0)
    widest_gap = np.max(np.diff(np.r_[angles, angles[0] + 360.0]))
    if 360.0 - widest_gap < MIN_ARC_DEG:
        return None
    lon, lat = _lonlat(centre[None, :], origin)[0]
    said = f"onto a circle of {radius / 1000:.1f} km around ({lat:.4f}, {lon:.4f})"
    return Signature(said, np.unique(rows[on]))


def displaced_ends(j: Jumps, group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The displaced end of each jump of an interference: after a vessel's first jump (into
    it), before its last (out of it, where it has more than one), both of those between; as
    the jumps (repeated where both ends count) and their [k, 2] lon/lat."""
    rows, ends = [], []
    for m in np.unique(j.mmsi[group]):
        mine = group[j.mmsi[group] == m]
        for i, k in enumerate(mine):
            if i < len(mine) - 1 or len(mine) == 1:
                rows.append(k)
                ends.append(j.after[k])
            if i > 0:
                rows.append(k)
                ends.append(j.before[k])
    return np.asarray(rows, np.int64), np.reshape(ends, (-1, 2))


def _ashore(group: np.ndarray, land: np.ndarray | None) -> Signature | None:
    if land is None or not land.any():
        return None
    return Signature("ashore", group[land])


def _metres(lonlat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[n, 2] east/north metres about the points' mean (flat: an area of tens of km), and it."""
    origin = lonlat.mean(axis=0)
    xy = (lonlat - origin) * M_PER_DEG
    xy[:, 0] *= np.cos(np.radians(origin[1]))
    return xy, origin


def _lonlat(xy: np.ndarray, origin: np.ndarray) -> np.ndarray:
    out = xy / M_PER_DEG
    out[:, 0] /= np.cos(np.radians(origin[1]))
    return out + origin


def _fit_circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """The least-squares circle through points (Kasa's algebraic fit): centre and radius."""
    a = np.column_stack([2 * xy, np.ones(len(xy))])
    b = np.sum(xy**2, axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(a, b, rcond=None)
    return np.array([cx, cy]), float(np.sqrt(max(c + cx**2 + cy**2, 0.0)))


def outline(points: np.ndarray) -> tuple[list[float], list[float]]:
    """The closed ring (lons, lats) around lon/lat `points`: their convex hull `OUTLINE_M`
    wider."""
    xy, origin = _metres(points)
    ring = shapely.MultiPoint(xy).convex_hull.buffer(OUTLINE_M, quad_segs=4).exterior
    lonlat = np.round(_lonlat(np.asarray(ring.coords), origin), 6)
    return lonlat[:, 0].tolist(), lonlat[:, 1].tolist()


def merged(groups: list[np.ndarray], j: Jumps) -> list[np.ndarray]:
    """The candidate areas of one interference as one: those sharing a vessel within a position
    jump's longest of one another (its start and its end, hours apart)."""
    out: list[np.ndarray] = []
    for g in sorted(groups, key=lambda g: j.t1[g].min()):
        mine = set(j.mmsi[g].tolist())
        for i, h in enumerate(out):
            near = j.t1[g].min() - j.t1[h].max() <= JUMP_MAX_S
            if near and mine & set(j.mmsi[h].tolist()):
                out[i] = np.union1d(h, g)
                break
        else:
            out.append(g)
    return out


def extended(group: np.ndarray, j: Jumps, s: EventSettings) -> np.ndarray:
    """An interference's jumps with every other jump during it (to `interference_within_s`
    either side) within `interference_radius_m` of its own: the vessels that came into the
    area while it lasted, one at a time."""
    during = np.flatnonzero(
        (j.t1 >= j.t1[group].min() - s.interference_within_s)
        & (j.t1 <= j.t1[group].max() + s.interference_within_s)
    )
    points = np.concatenate([j.before[group], j.after[group]])
    close = np.zeros(len(during), bool)
    for lon, lat in points[:: max(1, len(points) // 50)]:
        for ends in (j.before, j.after):
            close |= (
                haversine_m(lon, lat, ends[during, 0], ends[during, 1]) <= s.interference_radius_m
            )
    return np.union1d(group, during[close])


def share_displaced(fleet: Fleet, j: Jumps, rows: np.ndarray) -> float:
    """Of the vessels heard, while the displaced vessels (`rows`' vessels) were first
    displaced, within the outline of where they were before (`outline`), the share displaced:
    interference displaces every vessel of its area, a few vessels' own jumps do not."""
    vessels = np.unique(j.mmsi[rows])
    first = rows[np.unique(j.mmsi[rows], return_index=True)[1]]
    start, end = j.t0[first].min(), j.t1[first].max()
    lons, lats = outline(j.before[first])
    area = shapely.Polygon(np.column_stack([lons, lats]))
    reach = max(float(np.max(haversine_m(*j.before[first].mean(axis=0), lons, lats))), 1.0)
    near = fleet.heard.near(start, end, j.before[first].mean(axis=0)[None, :], reach)
    heard = fleet.heard
    inside = shapely.contains_xy(area, heard.lon[near], heard.lat[near])
    return len(vessels) / len(np.union1d(heard.mmsi[near[inside]], vessels))


def gnss_interference(fleet: Fleet, rules: EventRules) -> list[dict[str, Any]]:
    """The fleet's interference events: the candidate areas (`areas`) of one interference
    together (`merged`), where at least `interference_min_vessels` vessels were displaced alike
    (`signature`) and they are most of the vessels heard there (`share_displaced`), as event
    records naming those vessels."""
    s = rules.settings
    j = fleet_jumps(fleet, s)
    if len(j) == 0:
        return []
    events = []
    for group in merged(areas(j, s), j):
        group = extended(group, j, s)
        sig = signature(j, group, s, land_mask(j.after[group], rules.seen))
        if sig is None:
            continue
        rows = group[np.isin(j.mmsi[group], j.mmsi[sig.jumps])]
        if share_displaced(fleet, j, rows) >= s.interference_share:
            events.append(_record(fleet, j, rows, sig.how, s))
    return events


def _record(fleet: Fleet, j: Jumps, rows: np.ndarray, how: str, s: EventSettings) -> dict[str, Any]:
    """An interference as an event: its most displaced vessel, the others, its span from the
    first displaced report to the last jump, its outline (of where the vessels jumped from and
    to), and the centre of where they were when first displaced."""
    vessels, first = np.unique(j.mmsi[rows], return_index=True)
    most = int(j.mmsi[rows[np.argmax(j.metres[rows])]])
    others = [fleet.who(int(m)) for m in vessels if int(m) != most]
    points = np.concatenate([j.before[rows], j.after[rows]])
    centre = j.before[rows[first]].mean(axis=0)
    start, end = float(j.t1[rows].min()), float(j.t1[rows].max())
    said = (
        f"{len(vessels)} vessels displaced {np.median(j.metres[rows]) / 1000:.1f} km (median) "
        f"within {(j.t1[rows][first].max() - start) / 60:.0f} min, {how}"
    )
    return event_row(
        most, "gnss-interference", (start, end), len(rows), (centre[0], centre[1]),
        outline(points), len(vessels) / s.interference_min_vessels, said,
        identity=fleet.who(most), others=others,
    )  # fmt: skip
