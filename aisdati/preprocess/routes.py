"""Route clusters: group tracks into lanes by where they enter and leave, then by their shape.

The paper's `up`/`down`/`other` rule (`cluster.py`) fits the Florida Straits; where channels
wind or a harbour is crossed in every direction it puts nearly every track into `other`, and one
model trained on `other` mixes lanes that run in opposite directions. A route is a set of tracks
that start in one place, end in another and follow one path between them:

1. **Endpoints.** Each track is the point (entry, exit) in six dimensions: both ends as
   Earth-centred coordinates in km, so the euclidean distance is sqrt(d_entry² + d_exit²) with
   d the chord (the great-circle distance to 0.001% below 100 km), for any region, no projection.
   Density clustering finds the busy (entry, exit) pairs: by default HDBSCAN
   (`min_cluster_size` = `min_tracks`), which needs no distance scale, so the same defaults
   find the lanes of a fjord 200 km long and the ferry crossings of a harbour 2 km wide; with
   `eps_km` set, DBSCAN at that fixed radius. Entry and exit are ordered, so the two directions
   of a lane are far apart here: opposite directions are always separate routes.
2. **Split by shape.** Each candidate group may hold several paths between the same ends (either
   side of an island). Every track is resampled to `samples` points equally spaced along its
   length; the exact great-circle DTW of `aisdati.dtw`, read as the mean distance along the
   warping path (the project's reading of ε), compares them. Average-linkage clustering of (up
   to `max_sample` of) the group's tracks, cut at the shape tolerance τ, gives the paths; every
   track goes to the path whose medoid it is nearest.
3. **Merge.** Paths of different groups whose medoids start within τ of each other, end within
   τ, and are within τ in mean DTW in the same direction (closer than to the other's reverse)
   are one route: density clustering can cut a lane whose entries are spread out.
4. Paths with fewer than `min_tracks` tracks are not routes; their tracks, and those density
   clustering left as noise, have no route (`unrouted`). Routes are numbered `route-1`,
   `route-2`, ... by size, largest first, ties by their smallest track id.

τ is `eps_km` when given, otherwise `shape_fraction` of the group's median track length, at
least `shape_min_km`: 5% of a 175 km passage is 8.8 km (the channels that split it are tens of
km apart, a lane's own tracks a kilometre or two), and a harbour crossing of a few km gets the
floor of 0.5 km, the paper's ε. Resampling to 32 points makes each comparison 32 x 32 cells
whatever the report rate.

At the scale of a coast and a year (`benchmarks/routes_speed.py`: time linear in the number of
tracks) no step compares all pairs of tracks. Up to `EXACT_TRACKS` tracks the above is exact;
beyond, HDBSCAN runs on each track's `NEIGHBOURS` nearest endpoints (a k-d tree), on a seeded
sample of at most `DENSITY_SAMPLE` tracks that the others join. Everywhere, the shape split's
samples shrink when all groups together would need more than `SHAPE_PAIRS` DTWs, a track is
compared by DTW with only the `CANDIDATES` path medoids nearest in lock-step distance, the merge
looks only at paths whose ends are near (a k-d tree), and a route's spread is the median over a
sample of at most `max_sample` of its tracks. On the shipped samples (at most 2,144 tracks) all
of these give the routes of the exact steps.

Each route is described by its size, its entry and exit (the medians of its tracks' first and
last points), its median length, its medoid track (the member with the smallest summed distance
to the others: the route's most typical track, drawn in routes.png and written as its geometry)
and its spread (the median mean-DTW of its tracks to the medoid, km).

Deterministic: tracks are processed in the order of their ids (so the input order does not
matter), samples are drawn with `seed`, and ties go to the lower index.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np
import pandas as pd
import shapely
from numba import njit

from aisdati.dtw import pairs_mean_dtw_m, prepare_lonlat
from aisdati.geo import EARTH_RADIUS_M, arc_m, haversine_m, haversine_one_m, unit_vectors
from aisdati.memory import hand_back
from aisdati.tracks.schema import ROUTE_COLUMNS, ROUTE_PREFIX


@dataclass(frozen=True)
class RouteSettings:
    """How tracks are grouped into routes (see the module docstring)."""

    min_tracks: int = 5
    """Fewest tracks of a route; also HDBSCAN's min_cluster_size and DBSCAN's min_samples."""
    eps_km: float | None = None
    """None: HDBSCAN on the endpoints and a shape tolerance relative to the track length;
    a number: DBSCAN at this radius and this shape tolerance (mean DTW, km)."""
    seed: int = 0
    samples: int = 32
    """Points per resampled track for the shape DTW (32 x 32 cells per pair)."""
    max_sample: int = 128
    """Tracks of a group compared pairwise when splitting it by shape (a seeded sample)."""
    shape_fraction: float = 0.05
    shape_min_km: float = 0.5

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class Routes:
    """`labels[i]`: the route of track i (None: no route); `table`: one row per route, largest
    first (`ROUTE_COLUMNS`); `medoids[r]`: route r's medoid track, [n, 2] lon/lat."""

    labels: np.ndarray
    table: pd.DataFrame
    medoids: list[np.ndarray]
    seconds: dict[str, float] = field(default_factory=dict)
    """Wall time of each step: resample (`cluster_routes` only: ingest's tasks resample),
    endpoints, split, merge, describe."""


@dataclass
class TrackShapes:
    """What route clustering needs of each track, small whatever its number of reports: its
    first and last points [n, 2] and its line resampled to `samples` points [n, samples, 2].
    Ingest's tasks compute them where the tracks are made, so the process that clusters never
    holds every track's reports (at 100 M rows those were 3.4 GB)."""

    first: np.ndarray
    last: np.ndarray
    resampled: np.ndarray

    @classmethod
    def of(cls, lines: list[np.ndarray], samples: int) -> TrackShapes:
        ends = np.array([(xy[0], xy[-1]) for xy in lines]).reshape(-1, 2, 2)
        return cls(ends[:, 0], ends[:, 1], resample(lines, samples))

    @classmethod
    def joined(cls, parts: list[TrackShapes], samples: int) -> TrackShapes:
        if not parts:
            return cls(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, samples, 2)))
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))

    def take(self, rows: np.ndarray) -> TrackShapes:
        return TrackShapes(self.first[rows], self.last[rows], self.resampled[rows])

    def __len__(self) -> int:
        return len(self.first)


LinesOf = Callable[[np.ndarray], list[np.ndarray]]
"""Track rows (indices in the order the tracks were given) -> their [n, 2] lon/lat lines: how
route clustering fetches its few medoid tracks' reports."""


# ------------------------------------------------------------------------------ geometry
def earth_xyz_km(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Earth-centred coordinates in km of points in degrees, [..., 3]."""
    return EARTH_RADIUS_M / 1000.0 * unit_vectors(np.stack([lon, lat], axis=-1))


def resample(lines: list[np.ndarray], k: int) -> np.ndarray:
    """Each [n, 2] lon/lat line as k points equally spaced along its great-circle length
    (linear in lon/lat between reports, which are close): [len(lines), k, 2]. One compiled pass
    over all reports, as `np.interp` track by track would be (a Python loop per track is
    minutes at a million tracks)."""
    out = np.empty((len(lines), k, 2))
    if not lines:
        return out
    xy = np.ascontiguousarray(np.concatenate(lines), dtype=np.float64)
    ends = np.cumsum([len(line) for line in lines])
    _resample_all(xy, ends, np.linspace(0.0, 1.0, k), out)
    return out


@njit(cache=True)
def _resample_all(xy, ends, frac, out):  # pragma: no cover - compiled
    """`np.interp` of each track's lon and lat at `frac` of its length, bit for bit. The steps'
    lengths are computed here, point by point: numpy's haversine over all reports made a dozen
    temporaries of their size (28 M reports: 3 GB, and most of the time)."""
    start = 0
    for t in range(len(ends)):
        stop = ends[t]
        n = stop - start
        along = np.empty(n)
        along[0] = 0.0
        for p in range(start + 1, stop):
            step = haversine_one_m(xy[p - 1, 0], xy[p - 1, 1], xy[p, 0], xy[p, 1])
            along[p - start] = along[p - start - 1] + step
        if along[-1] <= 0:
            out[t, :, 0] = xy[start, 0]
            out[t, :, 1] = xy[start, 1]
        else:
            for q in range(len(frac)):
                x = frac[q] * along[-1]
                j = np.searchsorted(along, x, side="right") - 1
                for c in range(2):
                    if j >= n - 1:
                        out[t, q, c] = xy[stop - 1, c]
                        continue
                    y0, y1 = xy[start + j, c], xy[start + j + 1, c]
                    slope = (y1 - y0) / (along[j + 1] - along[j])
                    out[t, q, c] = slope * (x - along[j]) + y0
        start = stop


WHOLE_SET = 4
"""`ShapeDistance.pairs` hands the kernel all tracks once the tracks named are 1 / WHOLE_SET of
them or more."""


class ShapeDistance:
    """Mean great-circle DTW (km) between resampled tracks, both ways round."""

    def __init__(self, paths: np.ndarray) -> None:
        self.fwd = prepare_lonlat(paths)

    def pairs(self, i: np.ndarray, j: np.ndarray, reverse: bool = False) -> np.ndarray:
        """Distances of tracks i[p] to tracks j[p] (reversed). Only the tracks named are handed
        to the kernel, which checks every series it gets: the whole set each call would make
        the per-group calls quadratic in the number of tracks. A call that names a good part
        of them gets the whole set: copying the tracks named would cost more than the check."""
        if len(i) == 0:
            return np.zeros(0)
        used, inverse = np.unique(np.concatenate([i, j]), return_inverse=True)
        if len(used) * WHOLE_SET >= len(self.fwd) and not reverse:
            a, pairs = self.fwd, np.stack([i, j], axis=1)
        else:
            a, pairs = self.fwd[used], inverse.reshape(2, -1).T
        b = np.ascontiguousarray(a[:, ::-1]) if reverse else a
        pairs = np.ascontiguousarray(pairs.astype(np.int64))
        return pairs_mean_dtw_m(a, b, pairs) / 1000.0

    def grouped(self, i: list[np.ndarray], j: list[np.ndarray]) -> list[np.ndarray]:
        """`pairs` of each group (the tracks of `i`'s group to those of `j`'s, pair by pair), all
        from one kernel call: a call per group costs its start and checks again (a third of route
        clustering's DTW time at 1,000 groups)."""
        if not i:
            return []
        d = self.pairs(np.concatenate(i), np.concatenate(j))
        return np.split(d, np.cumsum([len(k) for k in i])[:-1])

    def matrices(self, sets: list[np.ndarray]) -> list[np.ndarray]:
        """The symmetric matrix of the distances among the tracks of each set (`grouped`)."""
        triu = [np.triu_indices(len(idx), 1) for idx in sets]
        parts = self.grouped(
            [idx[iu] for idx, (iu, _) in zip(sets, triu, strict=True)],
            [idx[ju] for idx, (_, ju) in zip(sets, triu, strict=True)],
        )
        out = []
        for idx, (iu, ju), part in zip(sets, triu, parts, strict=True):
            m = np.zeros((len(idx), len(idx)))
            m[iu, ju] = m[ju, iu] = part
            out.append(m)
        return out

    def nearest(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Position in `cols` of each row's nearest track (ties: the first). DTW only with
        the `CANDIDATES` nearest in lock-step distance (the mean distance between the i-th
        points, an upper bound of the mean DTW): all of them when there are no more, so a
        group's tracks cost a few DTWs each however many paths it has."""
        if len(cols) <= CANDIDATES:
            return np.argmin(self.cross(rows, cols), axis=1)
        out = np.empty(len(rows), dtype=np.int64)
        b = self.fwd[cols]  # unit vectors (`prepare_lonlat`)
        step = max(1, LOCKSTEP_CELLS // b[..., 0].size)  # rows per chunk: bounded memory
        for lo in range(0, len(rows), step):
            a = self.fwd[rows[lo : lo + step], None]
            lockstep = arc_m(np.linalg.norm(b[None] - a, axis=-1)).mean(axis=2)
            pick = np.sort(np.argsort(lockstep, axis=1, kind="stable")[:, :CANDIDATES], axis=1)
            rows_lo = np.repeat(rows[lo : lo + step], CANDIDATES)
            d = self.pairs(rows_lo, cols[pick.ravel()]).reshape(pick.shape)
            out[lo : lo + step] = pick[np.arange(len(pick)), np.argmin(d, axis=1)]
        return out

    def cross(self, rows: np.ndarray, cols: np.ndarray, reverse: bool = False) -> np.ndarray:
        """[len(rows), len(cols)] distances of tracks `rows` to tracks `cols`."""
        ii, jj = np.meshgrid(rows, cols, indexing="ij")
        return self.pairs(ii.ravel(), jj.ravel(), reverse).reshape(len(rows), len(cols))


# ---------------------------------------------------------------------------- clustering
EXACT_TRACKS = 20_000
"""Up to this many tracks HDBSCAN compares the endpoints of all pairs (scikit-learn's, O(n²):
3 s at 20,000); beyond, only each track's `NEIGHBOURS` nearest (`_hdbscan_knn`)."""
NEIGHBOURS = 16
"""Nearest neighbours of each track's endpoints that the large-scale HDBSCAN keeps."""
DENSITY_SAMPLE = 200_000
"""Tracks the large-scale HDBSCAN sees at most (`_sampled_hdbscan`)."""
SHAPE_PAIRS = 500_000
"""DTW pairs the shape split compares at most (about 2 s on 2 idle cores): when the groups'
samples of `max_sample` would need more, every group's sample shrinks to the size that fits."""
CANDIDATES = 3
"""Path medoids a track is compared with by DTW: the nearest in lock-step distance."""
LOCKSTEP_CELLS = 2_000_000
"""Point pairs one chunk of `ShapeDistance.nearest`'s lock-step distances holds (about 50 MB
of differences)."""


def endpoint_groups(first: np.ndarray, last: np.ndarray, settings: RouteSettings) -> np.ndarray:
    """Candidate group of each track from its entry and exit (-1: noise)."""
    n = len(first)
    if n < max(settings.min_tracks, 2):
        return np.full(n, -1)
    x = np.hstack([earth_xyz_km(first[:, 0], first[:, 1]), earth_xyz_km(last[:, 0], last[:, 1])])
    if settings.eps_km is None and n > EXACT_TRACKS:
        return _sampled_hdbscan(x, max(settings.min_tracks, 2), settings.seed)
    if settings.eps_km is None:
        from sklearn.cluster import HDBSCAN

        return HDBSCAN(min_cluster_size=max(settings.min_tracks, 2), copy=True).fit_predict(x)
    from sklearn.cluster import DBSCAN

    return DBSCAN(eps=settings.eps_km, min_samples=settings.min_tracks).fit_predict(x)


def _sampled_hdbscan(x: np.ndarray, min_cluster_size: int, seed: int) -> np.ndarray:
    """`_hdbscan_knn` of at most `DENSITY_SAMPLE` points (a seeded sample); every other point
    joins the group of its nearest sampled point when within that point's core distance (it
    would be one of its neighbours), else is noise. So a lane needs about min_cluster_size x
    n / DENSITY_SAMPLE tracks to be found beyond that many tracks."""
    from scipy.spatial import cKDTree

    n = len(x)
    if n <= DENSITY_SAMPLE:
        return _hdbscan_knn(x, min_cluster_size)[0]
    sample = np.sort(np.random.default_rng(seed).choice(n, DENSITY_SAMPLE, replace=False))
    sub, core = _hdbscan_knn(x[sample], min_cluster_size)
    dist, near = cKDTree(x[sample]).query(x, 1, workers=-1)
    labels = np.where(dist <= core[near], sub[near], -1)
    labels[sample] = sub
    return labels


def _hdbscan_knn(x: np.ndarray, min_cluster_size: int) -> tuple[np.ndarray, np.ndarray]:
    """HDBSCAN labels of points `x` from their `NEIGHBOURS` nearest neighbours (a k-d tree)
    instead of all pairs, which scikit-learn's own HDBSCAN takes: O(n²), hours at a million.

    The core distances are exact (the neighbours include the (min_cluster_size - 1)-th, the
    same core as scikit-learn's dense HDBSCAN at its default min_samples). The minimum spanning
    tree of the mutual reachability is exact within each connected part of the neighbour graph
    (its edges are short, so they are among the neighbours); the parts, every one of more than
    `NEIGHBOURS` points, are joined at a distance beyond any other, so each one is split (or
    kept) by its own hierarchy. The labels are scikit-learn's HDBSCAN of that graph
    (`hdbscan_labels`: the same steps compiled). Returns the labels and the core distances."""
    from aisdati.preprocess.hdbscan_graph import hdbscan_labels, neighbour_graph

    graph, dist = neighbour_graph(x, min(len(x) - 1, max(NEIGHBOURS, min_cluster_size)))
    labels = hdbscan_labels(graph, min_cluster_size, min_cluster_size - 1)
    return labels, dist[:, min_cluster_size - 1]


def _medoid(dist: np.ndarray) -> int:
    """Index of the row with the smallest sum of distances (ties: the lowest index)."""
    return int(np.argmin(dist.sum(axis=1)))


def _sample(idx: np.ndarray, size: int, rng: np.random.Generator) -> np.ndarray:
    if len(idx) <= size:
        return idx
    return np.sort(rng.choice(idx, size, replace=False))


def split_by_shape(
    idx: np.ndarray,
    sample: np.ndarray,
    dist: np.ndarray,
    shapes: ShapeDistance,
    tau: float,
) -> list[tuple[np.ndarray, int]]:
    """The paths within one candidate group, found among a sample of its tracks (`dist`: their
    distance matrix): (member track indices, medoid track index) each, every member assigned
    to its nearest path medoid."""
    if len(sample) == 1:
        return [(idx, int(sample[0]))]
    from scipy.cluster.hierarchy import fcluster, linkage
    from scipy.spatial.distance import squareform

    tree = linkage(squareform(dist, checks=False), method="average")
    sub = fcluster(tree, t=tau, criterion="distance")
    medoids = []
    for c in np.unique(sub):
        members = np.flatnonzero(sub == c)
        medoids.append(int(sample[members[_medoid(dist[np.ix_(members, members)])]]))
    medoids_arr = np.array(medoids)
    if len(medoids) == 1:
        return [(idx, medoids[0])]
    nearest = shapes.nearest(idx, medoids_arr)
    return [(idx[nearest == c], medoids[c]) for c in range(len(medoids)) if (nearest == c).any()]


def _members(groups: np.ndarray) -> list[np.ndarray]:
    """The ascending track indices of each group, groups in ascending order (-1 left out): one
    sort, where a scan of all tracks per group is quadratic."""
    order = np.flatnonzero(groups >= 0)
    order = order[np.argsort(groups[order], kind="stable")]
    return np.split(order, np.flatnonzero(np.diff(groups[order])) + 1) if len(order) else []


def _sample_size(sizes: list[int], cap: int) -> int:
    """The largest sample of each group, at most `cap`, whose shape split compares at most
    `SHAPE_PAIRS` pairs in all groups together (at least 2)."""

    def pairs(s: int) -> int:
        m = np.minimum(np.asarray(sizes, dtype=np.int64), s)
        return int((m * (m - 1) // 2).sum())

    lo, hi = 2, max(cap, 2)
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if pairs(mid) <= SHAPE_PAIRS else (lo, mid - 1)
    return lo


def _find(parent: list[int], i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


def merge_paths(
    paths: list[tuple[np.ndarray, int, float]],
    shapes: ShapeDistance,
    first: np.ndarray,
    last: np.ndarray,
) -> list[list[int]]:
    """Groups of paths (by position in `paths`) that are one lane: their medoids start within
    the smaller of the two tolerances of each other, end within it, and are within it in mean
    DTW, in the same direction (closer than to the other's reverse)."""
    n = len(paths)
    parent = list(range(n))
    if n > 1:
        med = np.array([m for _, m, _ in paths])
        tau = np.array([t for _, _, t in paths])
        iu, ju = _near_pairs(first[med], last[med], tau)
        limit = np.minimum(tau[iu], tau[ju])
        a, b = med[iu], med[ju]
        near = (
            haversine_m(first[a, 0], first[a, 1], first[b, 0], first[b, 1]) / 1000.0 <= limit
        ) & (haversine_m(last[a, 0], last[a, 1], last[b, 0], last[b, 1]) / 1000.0 <= limit)
        iu, ju, limit = iu[near], ju[near], limit[near]
        same = shapes.pairs(med[iu], med[ju])
        opposite = shapes.pairs(med[iu], med[ju], reverse=True)
        one_lane = (same <= limit) & (same < opposite)
        for i, j in zip(iu[one_lane], ju[one_lane], strict=True):
            ri, rj = _find(parent, int(i)), _find(parent, int(j))
            if ri != rj:
                parent[max(ri, rj)] = min(ri, rj)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(_find(parent, i), []).append(i)
    return list(groups.values())


def _near_pairs(
    first: np.ndarray, last: np.ndarray, tau: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs i < j (ascending) of paths whose medoids may start and end within tau[i] of each
    other, from a k-d tree instead of all pairs. Both great-circle distances within tau puts
    the (entry, exit) chords within sqrt(2) tau, so none is missed; the caller checks them."""
    from scipy.spatial import cKDTree

    x = np.hstack([earth_xyz_km(first[:, 0], first[:, 1]), earth_xyz_km(last[:, 0], last[:, 1])])
    balls = cKDTree(x).query_ball_point(x, np.sqrt(2.0) * tau * (1 + 1e-9) + 1e-9)
    iu = np.repeat(np.arange(len(x)), [len(b) for b in balls])
    ju = np.fromiter((j for b in balls for j in b), np.int64, len(iu))
    keep = iu < ju
    order = np.lexsort((ju[keep], iu[keep]))
    return iu[keep][order], ju[keep][order]


def cluster_routes(
    lines: list[np.ndarray],
    track_ids: np.ndarray,
    length_km: np.ndarray,
    settings: RouteSettings | None = None,
) -> Routes:
    """Routes of tracks given as [n, 2] lon/lat lines (with their distinct ids and lengths):
    `cluster_shapes` of their `TrackShapes`."""
    settings = settings or RouteSettings()
    started = time.perf_counter()
    shapes = TrackShapes.of(lines, settings.samples)
    resampled_s = round(time.perf_counter() - started, 3)
    routes = cluster_shapes(
        shapes, track_ids, length_km, lambda rows: [lines[i] for i in rows], settings
    )
    routes.seconds = {"resample": resampled_s, **routes.seconds}
    return routes


def cluster_shapes(
    tracks: TrackShapes,
    track_ids: np.ndarray,
    length_km: np.ndarray,
    lines_of: LinesOf,
    settings: RouteSettings | None = None,
) -> Routes:
    """Routes of tracks given by their `TrackShapes` (with their distinct ids and lengths;
    `lines_of` fetches the medoids' reports). The result depends on the tracks and the seed,
    not on the order they come in (they are processed in the order of their ids)."""
    settings = settings or RouteSettings()
    if settings.min_tracks < 2:
        raise ValueError("a route needs at least 2 tracks")
    track_ids = np.asarray(track_ids, dtype=np.int64)
    order = np.argsort(track_ids, kind="stable")
    if (order != np.arange(len(order))).any():
        return _in_id_order(order, tracks, track_ids, length_km, lines_of, settings)
    if len(tracks) == 0:
        return Routes(np.full(0, None, dtype=object), _empty_table(), [])
    length_km = np.asarray(length_km, dtype=np.float64)
    return _routes_in_id_order(tracks, track_ids, length_km, lines_of, settings)


class _Laps:
    """The wall time of each step of a run, from the end of the step before (`Routes.seconds`)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._clock = time.perf_counter()

    def lap(self, step: str) -> None:
        now = time.perf_counter()
        self.seconds[step] = round(now - self._clock, 3)
        self._clock = now


def _routes_in_id_order(
    tracks: TrackShapes,
    track_ids: np.ndarray,
    length_km: np.ndarray,
    lines_of: LinesOf,
    settings: RouteSettings,
) -> Routes:
    """`cluster_shapes` of at least one track, given in the order of their ids: the steps of
    the module docstring, each timed. One generator draws every sample, step after step."""
    laps = _Laps()
    first, last = tracks.first, tracks.last
    groups = endpoint_groups(first, last, settings)
    hand_back()  # what the density clustering freed, before the shapes' unit vectors are made
    laps.lap("endpoints")
    shapes = ShapeDistance(tracks.resampled)  # after: the density clustering's peak without it
    rng = np.random.default_rng(settings.seed)
    paths = _shape_paths(groups, shapes, length_km, settings, rng)
    laps.lap("split")
    routes = _merged_routes(paths, shapes, first, last, settings, rng)
    routes.sort(key=lambda r: (-len(r[0]), int(track_ids[r[0]].min())))
    laps.lap("merge")
    labels, table = _described(routes, tracks, track_ids, length_km, shapes, settings, rng)
    medoids = [medoid for _, medoid in routes]
    medoid_lines = lines_of(np.array(medoids, dtype=np.int64)) if medoids else []
    laps.lap("describe")
    return Routes(labels, table, medoid_lines, laps.seconds)


def _shape_paths(
    groups: np.ndarray,
    shapes: ShapeDistance,
    length_km: np.ndarray,
    settings: RouteSettings,
    rng: np.random.Generator,
) -> list[tuple[np.ndarray, int, float]]:
    """Step 2: every candidate group split by shape into paths (member track indices, medoid
    track index, the group's shape tolerance), from seeded samples of the groups compared all
    at once."""
    paths: list[tuple[np.ndarray, int, float]] = []
    members_of = _members(groups)
    size = _sample_size([len(idx) for idx in members_of], settings.max_sample)
    samples = [_sample(idx, size, rng) for idx in members_of]
    for idx, sample, dist in zip(members_of, samples, shapes.matrices(samples), strict=True):
        tau = _tolerance(length_km[idx], settings)
        for members, medoid in split_by_shape(idx, sample, dist, shapes, tau):
            paths.append((members, medoid, tau))
    return paths


def _described(
    routes: list[tuple[np.ndarray, int]],
    tracks: TrackShapes,
    track_ids: np.ndarray,
    length_km: np.ndarray,
    shapes: ShapeDistance,
    settings: RouteSettings,
    rng: np.random.Generator,
) -> tuple[np.ndarray, pd.DataFrame]:
    """Each track's route name (None: no route) and the routes table (`ROUTE_COLUMNS`), the
    routes (member track indices, medoid track index) numbered in the order given; a route's
    spread from a seeded sample of its tracks."""
    labels = np.full(len(tracks), None, dtype=object)
    some = [_sample(members, settings.max_sample, rng) for members, _ in routes]
    to_medoid = [np.full(len(s), medoid) for s, (_, medoid) in zip(some, routes, strict=True)]
    spreads = shapes.grouped(some, to_medoid)
    rows = []
    for number, ((members, medoid), spread) in enumerate(
        zip(routes, spreads, strict=True), start=1
    ):
        name = f"{ROUTE_PREFIX}{number}"
        labels[members] = name
        rows.append(
            {
                "route": name,
                "n_tracks": len(members),
                "entry_lon": float(np.median(tracks.first[members, 0])),
                "entry_lat": float(np.median(tracks.first[members, 1])),
                "exit_lon": float(np.median(tracks.last[members, 0])),
                "exit_lat": float(np.median(tracks.last[members, 1])),
                "median_length_km": float(np.median(length_km[members])),
                "medoid_track_id": int(track_ids[medoid]),
                "spread_km": float(np.median(spread)),
            }
        )
    table = pd.DataFrame(rows, columns=ROUTE_COLUMNS) if rows else _empty_table()
    return labels, table


def _in_id_order(
    order: np.ndarray,
    tracks: TrackShapes,
    track_ids: np.ndarray,
    length_km: np.ndarray,
    lines_of: LinesOf,
    settings: RouteSettings,
) -> Routes:
    """`cluster_shapes` of tracks not given in the order of their ids (`order` sorts them)."""
    routes = cluster_shapes(
        tracks.take(order),
        track_ids[order],
        np.asarray(length_km)[order],
        lambda rows: lines_of(order[rows]),
        settings,
    )
    routes.labels[order] = routes.labels.copy()
    return routes


def _merged_routes(
    paths: list[tuple[np.ndarray, int, float]],
    shapes: ShapeDistance,
    first: np.ndarray,
    last: np.ndarray,
    settings: RouteSettings,
    rng: np.random.Generator,
) -> list[tuple[np.ndarray, int]]:
    """The routes (member track indices, medoid track index) of the paths `merge_paths` joins,
    those with fewer than `min_tracks` tracks left out."""
    routes: list[tuple[np.ndarray, int]] = []
    for merged in merge_paths(paths, shapes, first, last):
        members = np.sort(np.concatenate([paths[p][0] for p in merged]))
        if len(members) < settings.min_tracks:
            continue
        medoid = paths[merged[0]][1]
        if len(merged) > 1:  # the merged paths' medoid nearest to (a sample of) all members
            candidates = np.array([paths[p][1] for p in merged])
            sample = _sample(members, settings.max_sample, rng)
            medoid = int(candidates[_medoid(shapes.cross(candidates, sample))])
        routes.append((members, medoid))
    return routes


def _tolerance(length_km: np.ndarray, settings: RouteSettings) -> float:
    if settings.eps_km is not None:
        return float(settings.eps_km)
    return max(settings.shape_min_km, settings.shape_fraction * float(np.median(length_km)))


def _empty_table() -> pd.DataFrame:
    return pd.DataFrame({c: pd.Series(dtype="object") for c in ROUTE_COLUMNS})


def lines_from_wkb(wkb: list[bytes]) -> list[np.ndarray]:
    """[n, 2] lon/lat arrays of WKB LineStrings (tracks.parquet's geometry)."""
    geoms = shapely.from_wkb(np.asarray(wkb, dtype=object))
    coords, owner = shapely.get_coordinates(geoms, return_index=True)
    cuts = np.flatnonzero(np.diff(owner)) + 1
    return np.split(coords, cuts) if len(coords) else []


# ------------------------------------------------------------------------ ingest settings
def settings_of(ingest_settings: Any) -> RouteSettings:
    """The route settings of an `IngestSettings`."""
    return RouteSettings(
        min_tracks=ingest_settings.route_min_tracks,
        eps_km=ingest_settings.route_eps_km,
        seed=ingest_settings.route_seed,
    )
