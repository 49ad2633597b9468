"""Exact dynamic time warping (DTW), for whole pairs of series and for two series growing together.

DATI's reward compares the imitated track with the expert track by DTW. The paper's official code
uses `fastdtw`, which is an approximation (its coarse-to-fine search can miss the optimal warping
path); here every value is the exact DTW: the sum of point distances along the optimal warping
path, with the recursion D[i, j] = d(a_i, b_j) + min(D[i-1, j-1], D[i-1, j], D[i, j-1]).

The reward needs the DTW of the two growing prefixes at every step of an episode. Recomputing it
from scratch costs O(t²) at step t, so O(n³) for an n-step episode. `IncrementalDTW` keeps only the
last row and the last column of the cumulative cost matrix: when both series grow by one point it
computes the new row and the new column from them in O(t), so a 900-step episode is O(n²) in all.

Ties between predecessors are broken deterministically, in the order diagonal (i-1, j-1), then
up (i-1, j), then left (i, j-1); `dtw_path`, `dtw_path_length` and `IncrementalDTW` all follow
this rule, so their paths and path lengths agree. Inner loops are compiled with numba.

Metrics: "euclidean" (points of any dimension) and "haversine" (points are (lon, lat) in degrees;
great-circle distance in metres on a sphere of radius `EARTH_RADIUS_M`, as the `haversine` package).

The compiled kernels do not check their indices (numba does no bounds checking), so every public
function checks its input in Python first and raises `ValueError` for what a kernel cannot take:
non-finite points (a NaN cost compares false with everything, so no predecessor ever wins) and
offsets, lengths or indices outside the arrays. The one back-track (`dtw_path`) is bounded by
construction as well: it never leaves the cost matrix and writes at most n + m - 1 cells, whatever
the costs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import config as numba_config
from numba import njit, prange

from aisdati.geo import EARTH_RADIUS_M, arc_m, unit_vectors

# The parallel kernels run on numba's own thread pool ("workqueue"), not OpenMP: with the OpenMP
# layer, one parallel kernel (validation's DTW after a DATI episode) left torch's next steps on
# two spinning threads, 13-200x slower on 2 cores (the "25x slower from episode 2" of issue 26).
numba_config.THREADING_LAYER = "workqueue"

_EUCLIDEAN, _HAVERSINE = 0, 1
_METRICS = {"euclidean": _EUCLIDEAN, "haversine": _HAVERSINE}
_DIAG, _UP, _LEFT = 0, 1, 2
PREPARE_CHUNK = 1_000_000
"""Points `prepare_lonlat` turns into unit vectors at a time: its temporaries are then tens of
MB, not several times the output (half a GB for the 270,000 track shapes of 100 M reports)."""


def _metric_code(metric: str) -> int:
    try:
        return _METRICS[metric]
    except (KeyError, TypeError):
        allowed = ", ".join(repr(m) for m in _METRICS)
        raise ValueError(f"unknown DTW metric {metric!r}; allowed: {allowed}") from None


def _check_finite(arr: np.ndarray, name: str) -> None:
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} holds non-finite values (NaN or inf): DTW needs finite points")


def _as_series(x, name: str, code: int) -> np.ndarray:
    """Validate a series as a finite, C-contiguous float64 array [n, d] (1-D input is read as
    d = 1)."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] == 0:
        raise ValueError(f"{name} must be a non-empty array [n, d], got shape {arr.shape}")
    if code != _EUCLIDEAN and arr.shape[1] != 2:
        raise ValueError(f"haversine DTW needs (lon, lat) points, {name} has shape {arr.shape}")
    _check_finite(arr, name)
    return np.ascontiguousarray(arr)


def _as_indices(x, name: str, size: int, length: int | None = None) -> np.ndarray:
    """Validate indices into an axis of `size` (and their number) as a C-contiguous int64 array."""
    arr = np.asarray(x)
    if arr.size and arr.dtype.kind not in "iu":
        raise ValueError(f"{name} must be integers, got {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype=np.int64)
    if length is not None and arr.shape[0] != length:
        raise ValueError(f"{name} must hold {length} values, got {arr.shape[0]}")
    if arr.size and (arr.min() < 0 or arr.max() >= size):
        raise ValueError(f"{name} must lie in [0, {size}), got [{arr.min()}, {arr.max()}]")
    return arr


def _check_pair(a, b, metric: str) -> tuple[np.ndarray, np.ndarray, int]:
    """Validate two series; return them prepared for `_point_dist`, and the metric code."""
    code = _metric_code(metric)
    a, b = _as_series(a, "a", code), _as_series(b, "b", code)
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"point dimensions differ: a is {a.shape}, b is {b.shape}")
    return _prepare(a, code), _prepare(b, code), code


@njit(cache=True)
def _prepare_point(src: np.ndarray, dst: np.ndarray, code: int) -> None:
    """Store point `src` in the form `_point_dist` reads: itself for euclidean, and
    (lon, lat, cos lat) in radians for haversine, so each cosine is taken once per point."""
    if code == _EUCLIDEAN:
        dst[:] = src
    else:
        lat = math.radians(src[1])
        dst[0] = math.radians(src[0])
        dst[1] = lat
        dst[2] = math.cos(lat)


@njit(cache=True)
def _prepare(x: np.ndarray, code: int) -> np.ndarray:
    """`_prepare_point` applied to every point of a series [n, d]."""
    out = np.empty((x.shape[0], x.shape[1] if code == _EUCLIDEAN else 3))
    for i in range(x.shape[0]):
        _prepare_point(x[i], out[i], code)
    return out


@njit(cache=True)
def _point_dist(a: np.ndarray, i: int, b: np.ndarray, j: int, code: int) -> float:
    """Distance between prepared points a[i] and b[j] under the metric `code`."""
    if code == _EUCLIDEAN:
        s = 0.0
        for k in range(a.shape[1]):
            diff = a[i, k] - b[j, k]
            s += diff * diff
        return math.sqrt(s)
    h = (
        math.sin((b[j, 1] - a[i, 1]) * 0.5) ** 2
        + a[i, 2] * b[j, 2] * math.sin((b[j, 0] - a[i, 0]) * 0.5) ** 2
    )
    return 2.0 * EARTH_RADIUS_M * math.asin(math.sqrt(min(max(h, 0.0), 1.0)))


@njit(cache=True)
def _best(diag: float, up: float, left: float) -> tuple[float, int]:
    """The smallest predecessor cost and its direction; ties prefer diagonal, then up, then left."""
    best, move = diag, _DIAG
    if up < best:
        best, move = up, _UP
    if left < best:
        best, move = left, _LEFT
    return best, move


@njit(cache=True)
def _cost_and_length(a: np.ndarray, b: np.ndarray, code: int) -> tuple[float, int]:
    """DTW cost and optimal-path length with O(m) memory (two rolling rows)."""
    n, m = a.shape[0], b.shape[0]
    inf = np.inf
    prev_d = np.full(m, inf)
    prev_l = np.zeros(m, dtype=np.int64)
    cur_d = np.empty(m)
    cur_l = np.empty(m, dtype=np.int64)
    for i in range(n):
        for j in range(m):
            d = _point_dist(a, i, b, j, code)
            if i == 0 and j == 0:
                cur_d[j], cur_l[j] = d, 1
                continue
            diag = prev_d[j - 1] if j > 0 else inf
            left = cur_d[j - 1] if j > 0 else inf
            best, move = _best(diag, prev_d[j], left)
            cur_d[j] = d + best
            if move == _DIAG:
                cur_l[j] = prev_l[j - 1] + 1
            elif move == _UP:
                cur_l[j] = prev_l[j] + 1
            else:
                cur_l[j] = cur_l[j - 1] + 1
        prev_d, cur_d = cur_d, prev_d
        prev_l, cur_l = cur_l, prev_l
    return prev_d[m - 1], prev_l[m - 1]


@njit(cache=True)
def _cost_and_path(a: np.ndarray, b: np.ndarray, code: int) -> tuple[float, np.ndarray]:
    """DTW cost and the optimal path (k x 2), from an n x m matrix of back-pointers."""
    n, m = a.shape[0], b.shape[0]
    inf = np.inf
    moves = np.empty((n, m), dtype=np.int8)
    prev_d = np.full(m, inf)
    cur_d = np.empty(m)
    for i in range(n):
        for j in range(m):
            d = _point_dist(a, i, b, j, code)
            if i == 0 and j == 0:
                cur_d[j] = d
                moves[i, j] = _DIAG
                continue
            diag = prev_d[j - 1] if j > 0 else inf
            left = cur_d[j - 1] if j > 0 else inf
            best, move = _best(diag, prev_d[j], left)
            cur_d[j] = d + best
            moves[i, j] = move
        prev_d, cur_d = cur_d, prev_d
    return prev_d[m - 1], _back_track(moves)


@njit(cache=True)
def _back_track(moves: np.ndarray) -> np.ndarray:
    """The path from (n-1, m-1) back to (0, 0) along the back-pointers, returned from (0, 0).
    On the first row only left is possible and on the first column only up (which finite costs
    always choose), so every step lowers i + j by at least one and stays in the matrix: at most
    n + m - 1 cells, whatever the back-pointers hold."""
    n, m = moves.shape
    path = np.empty((n + m - 1, 2), dtype=np.int64)
    i, j, k = n - 1, m - 1, 0
    while k < n + m - 1:
        path[k, 0], path[k, 1] = i, j
        k += 1
        if i == 0 and j == 0:
            break
        move = _LEFT if i == 0 else _UP if j == 0 else moves[i, j]
        if move == _DIAG:
            i -= 1
            j -= 1
        elif move == _UP:
            i -= 1
        else:
            j -= 1
    return path[:k][::-1].copy()


@njit(cache=True)
def _extend(
    a: np.ndarray,
    b: np.ndarray,
    a_point: np.ndarray,
    b_point: np.ndarray,
    t: int,
    row_d: np.ndarray,
    row_l: np.ndarray,
    col_d: np.ndarray,
    col_l: np.ndarray,
    code: int,
) -> None:
    """Append the points as a[t], b[t] (prepared) and turn the last row/column for prefixes of
    length t into those for length t + 1, in place.

    On entry row_d[j] = D[t-1, j] and col_d[i] = D[i, t-1] for 0 <= i, j < t (with path lengths in
    row_l/col_l); on exit they hold D[t, j] and D[i, t] for 0 <= i, j <= t.
    """
    _prepare_point(a_point, a[t], code)
    _prepare_point(b_point, b[t], code)
    if t == 0:
        d = _point_dist(a, 0, b, 0, code)
        row_d[0] = col_d[0] = d
        row_l[0] = col_l[0] = 1
        return
    corner_d, corner_l = row_d[t - 1], row_l[t - 1]  # D[t-1, t-1], before the new row
    _new_row(a, b, t, row_d, row_l, code)
    _new_column(a, b, t, col_d, col_l, code)
    # Corner (t, t): diagonal is the old corner, up is D[t-1, t], left is D[t, t-1].
    best, move = _best(corner_d, col_d[t - 1], row_d[t - 1])
    d = _point_dist(a, t, b, t, code)
    if move == _DIAG:
        length = corner_l + 1
    elif move == _UP:
        length = col_l[t - 1] + 1
    else:
        length = row_l[t - 1] + 1
    row_d[t] = col_d[t] = d + best
    row_l[t] = col_l[t] = length


@njit(cache=True)
def _new_row(
    a: np.ndarray, b: np.ndarray, t: int, row_d: np.ndarray, row_l: np.ndarray, code: int
) -> None:
    """Row i = t, j = 0..t-1 of the cost matrix (and its path lengths) in place of row t - 1:
    up is the old row, left is the new row."""
    inf = np.inf
    diag_d, diag_l = inf, 0
    for j in range(t):
        up_d, up_l = row_d[j], row_l[j]
        left_d = row_d[j - 1] if j > 0 else inf
        best, move = _best(diag_d, up_d, left_d)
        d = _point_dist(a, t, b, j, code)
        row_d[j] = d + best
        if move == _DIAG:
            row_l[j] = diag_l + 1
        elif move == _UP:
            row_l[j] = up_l + 1
        else:
            row_l[j] = row_l[j - 1] + 1
        diag_d, diag_l = up_d, up_l


@njit(cache=True)
def _new_column(
    a: np.ndarray, b: np.ndarray, t: int, col_d: np.ndarray, col_l: np.ndarray, code: int
) -> None:
    """Column j = t, i = 0..t-1 of the cost matrix (and its path lengths) in place of column
    t - 1: left is the old column, up is the new column."""
    inf = np.inf
    diag_d, diag_l = inf, 0
    for i in range(t):
        left_d, left_l = col_d[i], col_l[i]
        up_d = col_d[i - 1] if i > 0 else inf
        best, move = _best(diag_d, up_d, left_d)
        d = _point_dist(a, i, b, t, code)
        col_d[i] = d + best
        if move == _DIAG:
            col_l[i] = diag_l + 1
        elif move == _UP:
            col_l[i] = col_l[i - 1] + 1
        else:
            col_l[i] = left_l + 1
        diag_d, diag_l = left_d, left_l


def dtw(a, b, metric: str = "euclidean") -> float:
    """Exact DTW between series a [n, d] and b [m, d]: the summed point distance along the
    optimal warping path."""
    a, b, code = _check_pair(a, b, metric)
    return float(_cost_and_length(a, b, code)[0])


def dtw_path(a, b, metric: str = "euclidean") -> tuple[float, np.ndarray]:
    """Exact DTW cost and the optimal warping path, an int array [k, 2] of (i, j) pairs running
    from (0, 0) to (n - 1, m - 1)."""
    a, b, code = _check_pair(a, b, metric)
    cost, path = _cost_and_path(a, b, code)
    return float(cost), path


def dtw_path_length(a, b, metric: str = "euclidean") -> tuple[float, int]:
    """Exact DTW cost and the number of cells on the optimal path (the length of `dtw_path`)."""
    a, b, code = _check_pair(a, b, metric)
    cost, length = _cost_and_length(a, b, code)
    return float(cost), int(length)


def prepare_lonlat(series: np.ndarray) -> np.ndarray:
    """Lon/lat series of one length, [n, k, 2] degrees, in the form `pairs_mean_dtw_m` reads:
    [n, k, 3] unit vectors, so that comparing each series with many others takes each point's
    trigonometry once, and each cell costs a chord and its arc (the great-circle distance,
    exact: 2R asin(chord / 2)), half the haversine's work. Reversing a prepared series equals
    preparing the reversed one."""
    series = np.asarray(series, dtype=np.float64)
    if series.ndim != 3 or series.shape[1] == 0 or series.shape[2] != 2:
        raise ValueError(f"series must be lon/lat [n, k >= 1, 2], got shape {series.shape}")
    _check_finite(series, "series")
    n, k = series.shape[:2]
    out = np.empty((n, k, 3))
    rows = max(1, PREPARE_CHUNK // k)
    for lo in range(0, n, rows):  # in chunks: the trigonometry's temporaries stay small
        out[lo : lo + rows] = unit_vectors(series[lo : lo + rows])
    return out


def pairs_mean_dtw_m(a: np.ndarray, b: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Exact great-circle DTW / warping-path length (the mean distance in metres between matched
    points) of a[pairs[p, 0]] against b[pairs[p, 1]] for every p, on all cores; a and b are
    `prepare_lonlat`'s, pairs an int array [m, 2]."""
    for name, x in (("a", a), ("b", b)):
        if not (isinstance(x, np.ndarray) and x.dtype == np.float64 and x.ndim == 3):
            raise ValueError(f"{name} must be prepare_lonlat's float64 array [n, k, 3]")
        if x.shape[1] == 0 or x.shape[2] != 3:
            raise ValueError(f"{name} must be prepare_lonlat's [n, k >= 1, 3], got {x.shape}")
        _check_finite(x, name)
    pairs = np.asarray(pairs)
    if pairs.ndim != 2 or pairs.shape[1] != 2:
        raise ValueError(f"pairs must be an array [m, 2], got shape {pairs.shape}")
    first = _as_indices(pairs[:, 0], "pairs[:, 0]", len(a))
    second = _as_indices(pairs[:, 1], "pairs[:, 1]", len(b))
    return _prepared_pairs_mean(a, b, np.ascontiguousarray(np.stack([first, second], axis=1)))


@njit(cache=True, parallel=True)
def _prepared_pairs_mean(a, b, pairs):  # pragma: no cover - compiled
    out = np.empty(pairs.shape[0])
    n, m = a.shape[1], b.shape[1]
    no_tail = np.zeros(n)
    for p in prange(pairs.shape[0]):
        cost, length = _gc_cost_length(a[pairs[p, 0]], 0, n, b[pairs[p, 1]], 0, m, no_tail, np.inf)
        out[p] = cost / length
    return out


class IncrementalDTW:
    """Exact DTW of two series that grow together, one point each per `push`.

    After t pushes, `distance` equals `dtw(a[:t], b[:t])`. Each push costs O(t) work; memory is
    O(t) (the points, plus the last row and column of the cumulative cost matrix).
    """

    def __init__(self, metric: str = "euclidean", capacity: int = 256) -> None:
        self._code = _metric_code(metric)
        self.metric = metric
        self._capacity = max(int(capacity), 1)
        self.reset()

    def reset(self) -> None:
        """Forget all pushed points."""
        self._n = 0
        self._dim = 0
        self._a = np.empty((0, 0))
        self._b = np.empty((0, 0))
        self._row_d = np.empty(self._capacity)
        self._col_d = np.empty(self._capacity)
        self._row_l = np.empty(self._capacity, dtype=np.int64)
        self._col_l = np.empty(self._capacity, dtype=np.int64)

    def _grow(self, size: int) -> None:
        def bigger(arr: np.ndarray) -> np.ndarray:
            out = np.empty((size, *arr.shape[1:]), dtype=arr.dtype)
            out[: self._n] = arr[: self._n]
            return out

        self._a, self._b = bigger(self._a), bigger(self._b)
        self._row_d, self._col_d = bigger(self._row_d), bigger(self._col_d)
        self._row_l, self._col_l = bigger(self._row_l), bigger(self._col_l)

    def push(self, a_point, b_point) -> float:
        """Append one point to each series; return the DTW of the two prefixes."""
        pa = np.asarray(a_point, dtype=np.float64).reshape(-1)
        pb = np.asarray(b_point, dtype=np.float64).reshape(-1)
        if self._n == 0:
            if pa.shape != pb.shape or pa.size == 0:
                raise ValueError(
                    f"points must have equal non-zero size, got {pa.shape}, {pb.shape}"
                )
            if self._code != _EUCLIDEAN and pa.size != 2:
                raise ValueError(f"haversine DTW needs (lon, lat) points, got {pa.size} values")
            self._dim = pa.size
            width = self._dim if self._code == _EUCLIDEAN else 3
            self._a = np.empty((self._capacity, width))
            self._b = np.empty((self._capacity, width))
        elif pa.size != self._dim or pb.size != self._dim:
            raise ValueError(f"points must have {self._dim} values, got {pa.size} and {pb.size}")
        if not (np.isfinite(pa).all() and np.isfinite(pb).all()):
            raise ValueError(f"a point holds non-finite values (NaN or inf): {pa}, {pb}")
        t = self._n
        if t == self._a.shape[0]:
            self._grow(2 * t)
        _extend(
            self._a,
            self._b,
            pa,
            pb,
            t,
            self._row_d,
            self._row_l,
            self._col_d,
            self._col_l,
            self._code,
        )
        self._n = t + 1
        return float(self._row_d[t])

    _STATE_ARRAYS = ("_a", "_b", "_row_d", "_col_d", "_row_l", "_col_l")
    """The pushed points and the last row and column of the cost matrix: all a push reads."""

    def state_dict(self) -> dict[str, Any]:
        """What a restored instance needs to continue exactly (a training checkpoint taken
        mid-episode)."""
        n = self._n
        arrays = {k: getattr(self, k)[:n].copy() for k in self._STATE_ARRAYS}
        return {"n": n, "dim": self._dim, **arrays}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from `state_dict`; a state that does not fit (it comes from a file) is a
        `ValueError`, as the compiled push trusts the arrays it is given."""
        n, dim = int(state["n"]), int(state["dim"])
        saved = {key: np.asarray(state[key]) for key in self._STATE_ARRAYS}
        self._check_state(n, dim, saved)
        self.reset()
        self._n, self._dim = n, dim
        size = max(self._capacity, n)
        for key, values in saved.items():
            arr = np.empty((size, *values.shape[1:]), dtype=getattr(self, key).dtype)
            arr[:n] = values
            setattr(self, key, arr)

    def _check_state(self, n: int, dim: int, saved: dict[str, np.ndarray]) -> None:
        if n < 0:
            raise ValueError(f"DTW state: n must be >= 0, got {n}")
        if n and (dim < 1 or (self._code != _EUCLIDEAN and dim != 2)):
            raise ValueError(f"DTW state: {dim} values per point do not fit {self.metric} DTW")
        width = dim if self._code == _EUCLIDEAN else 3
        for key, values in saved.items():
            shape = (n, width) if key in ("_a", "_b") else (n,)
            empty = not n and values.ndim == len(shape) and not values.size
            if values.shape != shape and not empty:
                raise ValueError(f"DTW state: {key} must have shape {shape}, got {values.shape}")
            if key.endswith("_l"):
                ok = values.dtype.kind in "iu" and np.all((values >= 1) & (values <= 2 * n - 1))
            else:
                ok = values.dtype.kind == "f" and np.isfinite(values).all()
            if not ok:
                raise ValueError(f"DTW state: {key} holds values no DTW of {n} points has")

    @property
    def n(self) -> int:
        """Number of points pushed into each series."""
        return self._n

    @property
    def distance(self) -> float:
        """DTW of the two prefixes pushed so far (0 when empty)."""
        return float(self._row_d[self._n - 1]) if self._n else 0.0

    @property
    def path_length(self) -> int:
        """Number of cells on the optimal warping path of the prefixes (0 when empty)."""
        return int(self._row_l[self._n - 1]) if self._n else 0


# ------------------------------------------------------------------ batched great-circle DTW
ASIN_SERIES_MAX = 0.02
"""Half chords (unit sphere) up to which `_half_chord_arc_m` sums the series of asin instead of
calling it: arcs up to 255 km. There the first term left out, 63/2816 x^11, is below 2.3e-19 of
x, a five-hundredth of a double's rounding, so the arc is asin's within a rounding or two at
about half its cost: route clustering's 32 x 32 DTWs spent nearly half their time in asin, and
take a fifth less since."""


@njit(cache=True)
def _half_chord_arc_m(half: float) -> float:
    """Great-circle distance (m) of a chord between unit vectors, given half its length."""
    if half <= ASIN_SERIES_MAX:
        h2 = half * half
        series = 1.0 / 6.0 + h2 * (3.0 / 40.0 + h2 * (5.0 / 112.0 + h2 * (35.0 / 1152.0)))
        return 2.0 * EARTH_RADIUS_M * (half + half * h2 * series)
    return 2.0 * EARTH_RADIUS_M * math.asin(min(half, 1.0))


@njit(cache=True)
def _chord_m(a: np.ndarray, i: int, b: np.ndarray, j: int) -> float:
    dx = a[i, 0] - b[j, 0]
    dy = a[i, 1] - b[j, 1]
    dz = a[i, 2] - b[j, 2]
    return _half_chord_arc_m(0.5 * math.sqrt(dx * dx + dy * dy + dz * dz))


@njit(cache=True)
def _gc_cost_length(a, a_lo, n, b, b_lo, m, tail, beat):  # pragma: no cover - compiled
    """Great-circle DTW cost and path length of a[a_lo:a_lo+n] against b[b_lo:b_lo+m] (unit
    vectors), rolling rows. Gives up (inf, 0) once no cell of a row can lead to a mean of at
    most `beat` (inf: never): a path whose last cell in row i is (i, j), of cost D and length l,
    ends with cost >= D + tail[i] (`tail[i]` bounds rows i+1.. from below, each visited once)
    and length <= l + (n-1-i) + (m-1-j). Ties as `_best`. Each row's distances are computed in
    a loop of their own and the bound is checked only when there is one: both halve the time
    of the many small DTWs route clustering compares."""
    prev_d = np.full(m, np.inf)
    prev_l = np.zeros(m, dtype=np.int64)
    cur_d = np.empty(m)
    cur_l = np.empty(m, dtype=np.int64)
    row = np.empty(m)
    bounded = beat < np.inf
    for i in range(n):
        for j in range(m):
            row[j] = _chord_m(a, a_lo + i, b, b_lo + j)
        for j in range(m):
            if i == 0 and j == 0:
                cur_d[0] = row[0]
                cur_l[0] = 1
                continue
            best = np.inf
            move = 0
            if j > 0:
                best = prev_d[j - 1]
            if prev_d[j] < best:
                best = prev_d[j]
                move = 1
            if j > 0 and cur_d[j - 1] < best:
                best = cur_d[j - 1]
                move = 2
            cur_d[j] = row[j] + best
            if move == 0:
                cur_l[j] = prev_l[j - 1] + 1
            elif move == 1:
                cur_l[j] = prev_l[j] + 1
            else:
                cur_l[j] = cur_l[j - 1] + 1
        if bounded and not _row_alive(cur_d, cur_l, i, n, m, tail[i], beat):
            return np.inf, 0
        prev_d, cur_d = cur_d, prev_d
        prev_l, cur_l = cur_l, prev_l
    return prev_d[m - 1], prev_l[m - 1]


@njit(cache=True)
def _row_alive(cost, length, i, n, m, tail, beat):  # pragma: no cover - compiled
    """Whether some cell of row i can still lead to a mean of at most `beat`
    (`_gc_cost_length`)."""
    for j in range(m):
        longest = length[j] + (n - 1 - i) + (m - 1 - j)
        if (cost[j] + tail) * (1.0 - _ROUNDING) <= beat * longest:
            return True
    return False


_ROUNDING = 1e-9
"""Relative margin by which a bound must beat the best distance before the search trusts it:
far above the rounding of sums of a few thousand distances."""


@njit(cache=True, parallel=True)
def _pairs_mean(a, a_off, a_len, b, b_off, pair_a, pair_b):  # pragma: no cover - compiled
    out = np.empty(len(pair_a))
    no_tail = np.zeros(a_len.max())
    for p in prange(len(pair_a)):
        ia, ib = pair_a[p], pair_b[p]
        cost, length = _gc_cost_length(
            a, a_off[ia], a_len[p], b, b_off[ib], b_off[ib + 1] - b_off[ib], no_tail, np.inf
        )
        out[p] = cost / length
    return out


def _flatten(series: list[np.ndarray], name: str) -> tuple[np.ndarray, np.ndarray]:
    """Non-empty, finite lon/lat series as one array of unit vectors and their offsets."""
    if not series:
        raise ValueError(f"{name} must hold at least one series")
    checked = [_as_series(s, f"{name}[{k}]", _HAVERSINE) for k, s in enumerate(series)]
    offsets = np.zeros(len(checked) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(s) for s in checked])
    return unit_vectors(np.concatenate(checked)), offsets


def batch_mean_dtw_m(
    rollouts: np.ndarray, lengths: np.ndarray, tracks: list[np.ndarray], owner: np.ndarray
) -> np.ndarray:
    """Great-circle DTW / warping-path length (the mean distance in metres between matched
    points) of rollouts[b, :lengths[b]] against tracks[owner[b]], for every b, on all cores."""
    rollouts = np.asarray(rollouts, dtype=np.float64)
    if rollouts.ndim != 3 or rollouts.shape[2] != 2:
        raise ValueError(f"rollouts must be lon/lat [b, steps, 2], got shape {rollouts.shape}")
    _check_finite(rollouts, "rollouts")
    count, width = rollouts.shape[:2]
    lengths = _as_indices(np.asarray(lengths) - 1, "lengths - 1", width, count) + 1
    b, b_off = _flatten(list(tracks), "tracks")
    owner = _as_indices(owner, "owner", len(b_off) - 1, count)
    rolls = unit_vectors(rollouts).reshape(-1, 3)
    a_off = np.arange(count + 1, dtype=np.int64) * width
    pairs = np.arange(count, dtype=np.int64)
    return _pairs_mean(rolls, a_off, lengths, b, b_off, pairs, owner)


class _Swept:
    """Series flattened as unit vectors for the nearest search, with what `_sweep_min` reads:
    each series' axis of largest spread and its points' projections on it, sorted (`order`:
    the points' indices in that order, within the series)."""

    def __init__(self, series: list[np.ndarray], name: str) -> None:
        self.x, self.off = _flatten(series, name)
        count = len(self.off) - 1
        self.axis = np.empty((count, 3))
        self.proj = np.empty(len(self.x))
        self.order = np.empty(len(self.x), dtype=np.int64)
        for k in range(count):
            a, b = self.off[k], self.off[k + 1]
            pts = self.x[a:b]
            self.axis[k] = np.linalg.eigh(np.cov(pts.T) if b - a > 1 else np.eye(3))[1][:, -1]
            proj = pts @ self.axis[k]
            self.order[a:b] = np.argsort(proj, kind="stable")
            self.proj[a:b] = proj[self.order[a:b]]

    def lengths(self) -> np.ndarray:
        return np.diff(self.off)


@njit(cache=True)
def _sweep_min(a, a_lo, n, b, b_lo, m, proj, order, axis, cap_m, out):  # pragma: no cover
    """out[i] = min(cap_m, great-circle distance of a[a_lo + i] to the nearest point of
    b[b_lo:b_lo+m]), with the distance computed as `_chord_m` does. The chord between two
    points is at least the difference of their projections on `axis`, so from where a_i's
    projection falls among b's sorted ones only the points whose projection lies within the
    nearest chord so far (or the cap) need a look. Where a_i's projection falls is walked to
    from a_{i-1}'s: along a track it moves by a few places."""
    cap = 2.0 * math.sin(min(cap_m / (2.0 * EARTH_RADIUS_M), math.pi / 2))
    lo = 0
    for i in range(n):
        x0, x1, x2 = a[a_lo + i, 0], a[a_lo + i, 1], a[a_lo + i, 2]
        p = x0 * axis[0] + x1 * axis[1] + x2 * axis[2]
        while lo > 0 and proj[b_lo + lo - 1] >= p:
            lo -= 1
        while lo < m and proj[b_lo + lo] < p:
            lo += 1
        least = cap * cap
        reach = cap + 1e-12
        for step in (1, -1):
            j = lo if step == 1 else lo - 1
            while 0 <= j < m and abs(proj[b_lo + j] - p) <= reach:
                t = b_lo + order[b_lo + j]
                dx, dy, dz = x0 - b[t, 0], x1 - b[t, 1], x2 - b[t, 2]
                sq = dx * dx + dy * dy + dz * dz
                if sq < least:
                    least = sq
                    reach = math.sqrt(sq) + 1e-12
                j += step
        out[i] = cap_m if least >= cap * cap else _half_chord_arc_m(0.5 * math.sqrt(least))


@njit(cache=True)
def _mean_bound(amin, bmin, beat):  # pragma: no cover - compiled
    """A lower bound of the mean DTW of two series whose points lie amin / bmin (metres) from
    the other series; inf where it exceeds `beat`. A warping path of length L (max(n, m) to
    n + m - 1) enters each row once by a diagonal or vertical move (cost >= sum(amin)) and
    L - n columns by horizontal moves (cost >= the L - n smallest bmin), and the same with rows
    and columns swapped. The quick test first: sum(amin - beat) + sum(min(bmin - beat, 0)) > 0
    means every L's bound exceeds beat, with no sorting."""
    n, m = len(amin), len(bmin)
    over = beat * (1.0 + _ROUNDING)
    for x, y in ((amin, bmin), (bmin, amin)):
        if np.sum(x - over) + np.sum(np.minimum(y - over, 0.0)) > 0:
            return np.inf
    sa, sb = np.sort(amin), np.sort(bmin)
    big = max(n, m)
    x = sa.sum() + sb[: big - n].sum()
    y = sb.sum() + sa[: big - m].sum()
    bound = max(x, y) / big
    for length in range(big + 1, n + m):
        x += sb[length - 1 - n]
        y += sa[length - 1 - m]
        bound = min(bound, max(x, y) / length)
    return bound * (1.0 - _ROUNDING)


@njit(cache=True)
def _nearest_one(q, k, r, cand):  # pragma: no cover - compiled
    """Query k's nearest candidate (`_Swept` tuples q and r: x, off, axis, proj, order): the
    first candidate sets the best mean; every other one gets `_mean_bound` (the point minima
    capped a little above the best, which keeps the sweeps short and the bound valid); they
    are tried by increasing bound, each DTW abandoned once it cannot win, until a bound cannot
    beat the best. Equal means go to the smaller reference index."""
    qx, qoff, qaxis, qproj, qorder = q
    rx, roff, raxis, rproj, rorder = r
    lo, n = qoff[k], qoff[k + 1] - qoff[k]
    amin = np.zeros(n)
    tail = np.zeros(n)
    arg = cand[0]
    cost, length = _gc_cost_length(
        qx, lo, n, rx, roff[arg], roff[arg + 1] - roff[arg], tail, np.inf
    )
    best = cost / length
    cap = 2.0 * best + 1.0
    bound = np.full(len(cand), np.inf)
    for c in range(1, len(cand)):
        j = cand[c]
        b_lo, m = roff[j], roff[j + 1] - roff[j]
        bmin = np.empty(m)
        _sweep_min(qx, lo, n, rx, b_lo, m, rproj, rorder, raxis[j], cap, amin)
        _sweep_min(rx, b_lo, m, qx, lo, n, qproj, qorder, qaxis[k], cap, bmin)
        bound[c] = _mean_bound(amin, bmin, best)
    for c in np.argsort(bound, kind="mergesort"):
        j = cand[c]
        if bound[c] > best:
            break
        if bound[c] == best and j > arg:
            continue
        b_lo, m = roff[j], roff[j + 1] - roff[j]
        _sweep_min(qx, lo, n, rx, b_lo, m, rproj, rorder, raxis[j], cap, amin)
        tail[n - 1] = 0.0
        for i in range(n - 2, -1, -1):
            tail[i] = tail[i + 1] + amin[i + 1]
        cost, length = _gc_cost_length(qx, lo, n, rx, b_lo, m, tail, best)
        if length > 0 and (cost / length < best or (cost / length == best and j < arg)):
            best, arg = cost / length, j
    return best, arg


@njit(cache=True, parallel=True)
def _nearest(q, r, cand, cand_off):  # pragma: no cover - compiled
    """`_nearest_one` of every query with candidates, the queries shared among the cores."""
    nq = len(cand_off) - 1
    best = np.full(nq, np.inf)
    arg = np.full(nq, -1, dtype=np.int64)
    for k in prange(nq):
        if cand_off[k + 1] > cand_off[k]:
            best[k], arg[k] = _nearest_one(q, k, r, cand[cand_off[k] : cand_off[k + 1]])
    return best, arg


def _by_likeness(q: _Swept, k: int, r: _Swept, cand: np.ndarray) -> np.ndarray:
    """Query k's candidates, those most like it first: by the summed distance between the
    points at 0, 1/4, .. 4/4 of each series (only the first matters: it sets the best mean
    that the bounds must beat, so a near one keeps every sweep short)."""
    at = np.linspace(0.0, 1.0, 5)
    mine = q.x[q.off[k] + np.rint(at * (q.off[k + 1] - q.off[k] - 1)).astype(np.int64)]
    theirs = r.off[cand, None] + np.rint(at * (r.lengths()[cand, None] - 1)).astype(np.int64)
    unlike = np.linalg.norm(r.x[theirs] - mine, axis=2).sum(axis=1)
    return cand[np.argsort(unlike, kind="stable")]


def nearest_mean_dtw_m(
    queries: list[np.ndarray], references: list[np.ndarray], candidates: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Exact nearest reference of each query in mean great-circle DTW (metres), searching only
    `candidates[k]` (reference indices) for query k. Returns (distance, index), the smaller
    index among equal distances; inf and -1 for a query without candidates. Pruning is exact
    (`_nearest_one`): the candidate most like the query first (`_by_likeness`), then the others by a
    lower bound from each point's distance to the other series (`_mean_bound`), found by a
    sweep along each series' main axis (`_sweep_min`), with each DTW abandoned once it cannot
    win (`_gc_cost_length`)."""
    q, r = _Swept(list(queries), "queries"), _Swept(list(references), "references")
    if len(candidates) != len(queries):
        raise ValueError(f"{len(queries)} queries, {len(candidates)} candidate lists")
    order = [
        _by_likeness(q, k, r, np.unique(_as_indices(c, f"candidates[{k}]", len(r.off) - 1)))
        for k, c in enumerate(candidates)
    ]
    cand_off = np.zeros(len(candidates) + 1, dtype=np.int64)
    cand_off[1:] = np.cumsum([len(o) for o in order])
    flat = np.concatenate(order).astype(np.int64) if order else np.empty(0, np.int64)
    swept = [(s.x, s.off, s.axis, s.proj, s.order) for s in (q, r)]
    return _nearest(*swept, flat, cand_off)


def matched_distances(track: np.ndarray, other: np.ndarray) -> np.ndarray:
    """For each point of `track` (lon, lat), the great-circle distance (m) to the nearest point
    of `other` that the optimal warping path matches it with: where along the track it strays."""
    _, path = dtw_path(other, track, "haversine")
    a, b = other[path[:, 0]], track[path[:, 1]]
    d = arc_m(np.linalg.norm(unit_vectors(a) - unit_vectors(b), axis=1))
    out = np.full(len(track), np.inf)
    np.minimum.at(out, path[:, 1], d)
    return out
