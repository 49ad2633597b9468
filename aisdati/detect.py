"""Detection of abnormal tracks (section 6.2 of the paper): rollouts -> scores -> flags -> outputs.

For each test track, the model that learnt the traffic entering where the track enters is rolled
out K times from the track's first point, for as many steps as the track has (the agent acts with
its own latent noise, through the spherical rule, sticking at its region's box). A rollout's
distance to the track is the great-circle DTW divided by the number of cells on the optimal
warping path: the mean distance in metres between matched points, so long and short tracks
compare (the same reading as ε in training). A track's raw score is the smallest of its K
distances (K = 1 is the paper's protocol; the agent is stochastic, so more rollouts give a fairer
"could the model have generated this?"). Raw scores are divided by their maximum over the test
set, as in the paper, and tracks above `threshold` (paper: Λ = 0.75), or in the top `top_percent`,
are flagged. For every track the point of maximum local distance along the best warping path
tells where it deviates most.

Default test set (section 6.2): tracks of the `other` cluster, not used in training, whose first
point lies within `near_km` (default 10 km) of some training track's first point: a model of `up`
traffic judges tracks that enter from the same boundary. With several models, each track goes to
the model with the nearest training start.
"""

from __future__ import annotations

import json
import math
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import torch
from numba import njit, prange

from aisdati.dtw import dtw_path, dtw_path_length
from aisdati.errors import UserError
from aisdati.geo import EARTH_RADIUS_M, haversine_m
from aisdati.model.card import card_warnings, training_mask, validate_ais_card
from aisdati.model.checkpoint import atomic_write_bytes, load_networks
from aisdati.model.dati import DATIConfig
from aisdati.model.networks import DATINetworks
from aisdati.model.rules import BoxScaler, SphericalRule
from aisdati.trackdata import CLUSTERS, Track, load_tracks, read_track_table

SCORES_SCHEMA = pa.schema(
    [
        ("track_id", pa.int64()),
        ("mmsi", pa.int64()),
        ("model", pa.string()),
        ("n_points", pa.int64()),
        ("score_m", pa.float64()),
        ("score", pa.float64()),
        ("flagged", pa.bool_()),
        ("rank", pa.int64()),
        ("max_dev_m", pa.float64()),
        ("max_dev_lon", pa.float64()),
        ("max_dev_lat", pa.float64()),
        ("max_dev_index", pa.int64()),
    ]
)
"""scores.parquet, one row per test track, sorted by rank (1 = most abnormal). score_m: best-of-K
mean great-circle distance along the warping path (metres); score: score_m / max over the test
set; max_dev_*: the track point with the largest distance to its matched rollout point."""


@dataclass
class AISModel:
    name: str
    nets: DATINetworks
    config: DATIConfig
    card: dict[str, Any]
    warnings: list[str] = field(default_factory=list)
    """What the operator should know before trusting this model (e.g. unfinished training)."""

    @property
    def rule(self) -> SphericalRule:
        r = self.card["rule"]
        return SphericalRule(
            max_sog=float(r["max_sog_kn"]),
            max_dt_h=float(r["max_dt_h"]),
            cog_center=float(r.get("cog_center_deg", 180.0)),
        )

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        reg = self.card["region"]
        return (
            np.array([reg["lon"][0], reg["lat"][0]], np.float64),
            np.array([reg["lon"][1], reg["lat"][1]], np.float64),
        )

    @property
    def start_points(self) -> np.ndarray:
        return np.asarray(self.card["data"]["start_points"], np.float64).reshape(-1, 2)

    @property
    def training_ids(self) -> set[int]:
        return {int(i) for i in self.card["data"]["track_ids"]}

    def training_mask(self, tracks: pd.DataFrame) -> np.ndarray:
        """Which rows of a tracks table are this model's training tracks (by vessel and time
        span where the card has them: track ids change when the data is ingested again)."""
        return training_mask(self.card, tracks)

    def contains(self, points: np.ndarray) -> np.ndarray:
        lo, hi = self.bounds
        return np.all((points >= lo) & (points <= hi), axis=-1)


@dataclass(frozen=True)
class DetectSettings:
    data_dir: Path
    models_dir: Path
    out_dir: Path
    models: tuple[str, ...] = ()
    """Model names (<models_dir>/<name>.pt/.json); empty: every model in the folder."""
    cluster: str = "other"
    """Cluster of the test tracks: up, down, other or all."""
    track_ids: tuple[int, ...] = ()
    """Explicit test tracks (overrides the cluster and the start rule)."""
    rollouts: int = 10
    threshold: float = 0.75
    top_percent: float | None = None
    near_km: float = 10.0
    seed: int = 0
    labels: Path | None = None
    """CSV of hand labels (track_id or mmsi + start, label 0/1) for precision/recall/F1/AUC."""


@dataclass
class Detection:
    scores: pd.DataFrame
    tracks: list[Track]
    rollouts: list[np.ndarray]
    """The best rollout per track, in the order of `tracks`."""
    models: list[AISModel]
    timings: dict[str, float] = field(default_factory=dict)
    settings: DetectSettings | None = None
    metrics: dict[str, Any] | None = None


# ------------------------------------------------------------------------------------ models
def load_ais_model(stem: Path) -> AISModel:
    weights = stem.with_suffix(".pt")
    if weights.is_file():
        with weights.open("rb") as fh:
            if fh.read(2) != b"PK":  # torch.save writes a zip archive
                raise UserError(f"{weights} is not a model weights file (damaged or foreign)")
    nets, config, card = load_networks(stem)
    needed = ("rule", "region", "data")
    if card.get("kind") != "ais" or any(k not in card for k in needed):
        raise UserError(f"{stem}.json is not an AIS model card (train one with `aisdati train`)")
    if nets.members != 1 or card.get("decision_dim", 3) != 3:
        raise UserError(f"{stem}: expected a single-member model with 3 decisions")
    validate_ais_card(card, stem.with_suffix(".json"))
    return AISModel(stem.name, nets, config, card, card_warnings(card, stem.name))


def load_models(models_dir: Path, names: Sequence[str]) -> list[AISModel]:
    if names:
        stems = [models_dir / n for n in names]
    else:
        stems = sorted(p.with_suffix("") for p in models_dir.glob("*.json"))
        stems = [s for s in stems if s.with_suffix(".pt").is_file()]
        if not stems:
            raise UserError(f"no models in {models_dir}: run `aisdati train --cluster up` first")
    return [load_ais_model(s) for s in stems]


# --------------------------------------------------------------------------------- test set
def select_test_tracks(
    settings: DetectSettings, models: Sequence[AISModel]
) -> tuple[list[int], list[int]]:
    """Test track ids and, for each, the index of the model that judges it."""
    table = read_track_table(settings.data_dir)
    if settings.track_ids:
        missing = set(settings.track_ids) - set(table["track_id"])
        if missing:
            raise UserError(f"tracks not in {settings.data_dir}: {sorted(missing)[:5]}")
        table = table[table["track_id"].isin(settings.track_ids)]
    elif settings.cluster != "all":
        if settings.cluster not in CLUSTERS:
            raise UserError(
                f"unknown cluster {settings.cluster!r}; choose from {', '.join(CLUSTERS)} or all"
            )
        table = table[table["cluster"] == settings.cluster]
        if table.empty:
            raise UserError(f"no tracks in cluster {settings.cluster!r} in {settings.data_dir}")
    ids = table["track_id"].to_numpy()
    starts = table[["lon0", "lat0"]].to_numpy(np.float64) if "lon0" in table else None
    if starts is None:
        starts = np.array([t.positions[0] for t in load_tracks(settings.data_dir, ids)])
    # distance from each start to each model's nearest training start (km)
    near = np.full((len(ids), len(models)), np.inf)
    for m, model in enumerate(models):
        sp = model.start_points
        for lo in range(0, len(sp), 256):
            chunk = sp[lo : lo + 256]
            d = haversine_m(starts[:, None, 0], starts[:, None, 1], chunk[:, 0], chunk[:, 1])
            near[:, m] = np.minimum(near[:, m], d.min(axis=1) / 1000.0)
        if not settings.track_ids:
            trained = model.training_mask(table)
            near[trained, m] = np.inf  # a model does not judge its own training tracks
    inside = np.zeros(len(ids), dtype=bool)
    for model in models:
        inside |= model.contains(starts)
    if not inside.any():
        lo, hi = models[0].bounds
        raise UserError(
            f"no test track starts inside the model's region (lon {lo[0]:.2f}..{hi[0]:.2f}, "
            f"lat {lo[1]:.2f}..{hi[1]:.2f}): is the model from another region?"
        )
    best = near.argmin(axis=1)
    dist = near[np.arange(len(ids)), best]
    keep = np.ones(len(ids), dtype=bool) if settings.track_ids else dist <= settings.near_km
    if not keep.any():
        raise UserError(
            f"no test tracks start within {settings.near_km:g} km of the training tracks' starts "
            "(training tracks are never test tracks); raise --near-km or pass --cluster all"
        )
    return [int(i) for i in ids[keep]], [int(b) for b in best[keep]]


# ---------------------------------------------------------------------------------- rollouts
def generate(
    model: AISModel,
    starts: np.ndarray,
    horizons: np.ndarray,
    rollouts: int,
    seed: int = 0,
) -> np.ndarray:
    """K rollouts from each start, all in one batch: positions [N * K, max horizon + 1, 2], rollout
    k of start i at row i * K + k; rows past their horizon hold the last position."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small matmuls: extra threads cost 10x on 2 busy cores
    try:
        return _generate(model, starts, horizons, rollouts, seed)
    finally:
        torch.set_num_threads(threads)


def _generate(
    model: AISModel, starts: np.ndarray, horizons: np.ndarray, rollouts: int, seed: int
) -> np.ndarray:
    nets, cfg, rule = model.nets, model.config, model.rule
    lo, hi = model.bounds
    scaler = BoxScaler(lo, hi, unit_low=0.0)
    n = len(starts) * rollouts
    pos = np.repeat(np.asarray(starts, np.float64), rollouts, axis=0)
    steps = int(np.max(horizons))
    out = np.empty((n, steps + 1, 2))
    out[:, 0] = pos
    gen = torch.Generator().manual_seed(int(seed))
    latent = cfg.network.latent_dim
    eta = torch.zeros(1, n, latent)
    limit = np.repeat(np.asarray(horizons), rollouts)
    for t in range(steps):
        draw = torch.randn((1, n, latent), generator=gen) * cfg.noise_sigma
        if cfg.noise == "ou":
            eta = eta - cfg.ou_theta * eta * cfg.ou_dt + draw * math.sqrt(cfg.ou_dt)
        else:
            eta = draw
        state = torch.as_tensor(np.clip(scaler.scale(pos), 0.0, 1.0), dtype=torch.float32)[None]
        tt = torch.full((1, n, 1), float(t))
        with torch.no_grad():
            action = nets.forward_actor(state, eta, nets.time_features(tt))[0].numpy()
        decision = rule.decision_scaler.unscale(np.clip(action, -1.0, 1.0))
        proposed = rule.step(pos, decision)
        ok = np.all(np.isfinite(proposed), axis=1) & np.all(
            (proposed >= lo) & (proposed <= hi), axis=1
        )
        ok &= t < limit
        pos = np.where(ok[:, None], proposed, pos)
        out[:, t + 1] = pos
    return out


def _unit_vectors(lonlat: np.ndarray) -> np.ndarray:
    lon, lat = np.radians(lonlat[..., 0]), np.radians(lonlat[..., 1])
    return np.ascontiguousarray(
        np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)
    )


@njit(cache=True, parallel=True)
def _batch_dtw(rolls, lengths, tracks, offsets, owner):  # pragma: no cover - compiled
    """Exact great-circle DTW cost and path length of rollout b (its first lengths[b] points)
    against track owner[b] (tracks[offsets[o]:offsets[o + 1]]), for every b in parallel.
    Points are unit vectors; the great-circle distance 2R asin(chord / 2) equals the haversine
    formula. Ties prefer diagonal, then up, then left, as `aisdati.dtw`."""
    nb = rolls.shape[0]
    cost = np.empty(nb)
    plen = np.empty(nb, dtype=np.int64)
    for b in prange(nb):
        o = owner[b]
        lo, hi = offsets[o], offsets[o + 1]
        m = hi - lo
        n = lengths[b]
        prev_d = np.full(m, np.inf)
        prev_l = np.zeros(m, dtype=np.int64)
        cur_d = np.empty(m)
        cur_l = np.empty(m, dtype=np.int64)
        for i in range(n):
            ax, ay, az = rolls[b, i, 0], rolls[b, i, 1], rolls[b, i, 2]
            for j in range(m):
                dx = ax - tracks[lo + j, 0]
                dy = ay - tracks[lo + j, 1]
                dz = az - tracks[lo + j, 2]
                half = 0.5 * math.sqrt(dx * dx + dy * dy + dz * dz)
                d = 2.0 * EARTH_RADIUS_M * math.asin(min(half, 1.0))
                if i == 0 and j == 0:
                    cur_d[0] = d
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
                cur_d[j] = d + best
                if move == 0:
                    cur_l[j] = prev_l[j - 1] + 1
                elif move == 1:
                    cur_l[j] = prev_l[j] + 1
                else:
                    cur_l[j] = cur_l[j - 1] + 1
            prev_d, cur_d = cur_d, prev_d
            prev_l, cur_l = cur_l, prev_l
        cost[b] = prev_d[m - 1]
        plen[b] = prev_l[m - 1]
    return cost, plen


def batch_mean_dtw_m(
    rollouts: np.ndarray, lengths: np.ndarray, tracks: Sequence[np.ndarray], owner: np.ndarray
) -> np.ndarray:
    """`mean_dtw_m(rollouts[b, :lengths[b]], tracks[owner[b]])` for every b, on all cores."""
    offsets = np.zeros(len(tracks) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(t) for t in tracks])
    flat = _unit_vectors(np.concatenate(tracks))
    cost, plen = _batch_dtw(
        _unit_vectors(rollouts),
        np.asarray(lengths, np.int64),
        flat,
        offsets,
        np.asarray(owner, np.int64),
    )
    return cost / plen


def mean_dtw_m(a: np.ndarray, b: np.ndarray) -> float:
    """Great-circle DTW / warping-path length: the mean distance (m) between matched points."""
    cost, length = dtw_path_length(a, b, "haversine")
    return cost / length


def max_deviation(rollout: np.ndarray, track: np.ndarray) -> tuple[float, int]:
    """The largest local distance (m) along the optimal warping path, and the track index."""
    _, path = dtw_path(rollout, track, "haversine")
    d = haversine_m(
        rollout[path[:, 0], 0], rollout[path[:, 0], 1], track[path[:, 1], 0], track[path[:, 1], 1]
    )
    k = int(np.argmax(d))
    return float(d[k]), int(path[k, 1])


def flag(scores: np.ndarray, threshold: float, top_percent: float | None) -> np.ndarray:
    if top_percent is not None:
        count = math.ceil(len(scores) * top_percent / 100.0)
        order = np.argsort(-scores, kind="stable")
        flagged = np.zeros(len(scores), dtype=bool)
        flagged[order[:count]] = True
        return flagged
    return scores > threshold


def check_settings(settings: DetectSettings) -> None:
    if not (0.0 < settings.threshold <= 1.0):
        raise UserError(f"--threshold must be in (0, 1], got {settings.threshold:g}")
    if settings.top_percent is not None and not (0.0 < settings.top_percent <= 100.0):
        raise UserError(f"--top-percent must be in (0, 100], got {settings.top_percent:g}")
    if settings.rollouts < 1:
        raise UserError(f"--rollouts must be at least 1, got {settings.rollouts}")
    if settings.near_km <= 0:
        raise UserError(f"--near-km must be positive, got {settings.near_km:g}")


def detect(settings: DetectSettings) -> Detection:
    """Score the test tracks; see the module docstring."""
    check_settings(settings)
    if settings.labels is not None:
        read_labels(settings.labels)  # fail on a bad file before the rollouts
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    models = load_models(settings.models_dir, settings.models)
    ids, owner = select_test_tracks(settings, models)
    tracks = load_tracks(settings.data_dir, ids)
    timings["load_s"] = time.perf_counter() - t0
    n = len(tracks)
    k = settings.rollouts
    raw = np.full(n, np.nan)
    best_rollouts: list[np.ndarray] = [np.empty((0, 2))] * n
    t1 = time.perf_counter()
    gen_s = 0.0
    for m, model in enumerate(models):
        idx = [i for i in range(n) if owner[i] == m]
        if not idx:
            continue
        starts = np.array([tracks[i].positions[0] for i in idx])
        horizons = np.array([tracks[i].steps for i in idx])
        tg = time.perf_counter()
        paths = generate(model, starts, horizons, k, settings.seed + m)
        gen_s += time.perf_counter() - tg
        dists = batch_mean_dtw_m(
            paths,
            np.repeat(horizons + 1, k),
            [tracks[i].positions for i in idx],
            np.repeat(np.arange(len(idx)), k),
        ).reshape(len(idx), k)
        for j, i in enumerate(idx):
            best = int(np.argmin(dists[j]))
            raw[i] = dists[j, best]
            best_rollouts[i] = paths[j * k + best, : horizons[j] + 1].copy()
    timings["rollout_s"] = gen_s
    timings["score_s"] = time.perf_counter() - t1 - gen_s
    top = float(np.max(raw)) if n else 1.0
    norm = raw / top if top > 0 else np.zeros(n)
    flagged = flag(norm, settings.threshold, settings.top_percent)
    order = np.argsort(-norm, kind="stable")
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(1, n + 1)
    devs = [max_deviation(best_rollouts[i], tracks[i].positions) for i in range(n)]
    scores = pd.DataFrame(
        {
            "track_id": [t.track_id for t in tracks],
            "mmsi": [t.mmsi for t in tracks],
            "model": [models[o].name for o in owner],
            "n_points": [len(t.positions) for t in tracks],
            "score_m": raw,
            "score": norm,
            "flagged": flagged,
            "rank": rank,
            "max_dev_m": [d for d, _ in devs],
            "max_dev_lon": [tracks[i].positions[j, 0] for i, (_, j) in enumerate(devs)],
            "max_dev_lat": [tracks[i].positions[j, 1] for i, (_, j) in enumerate(devs)],
            "max_dev_index": [j for _, j in devs],
        }
    )
    timings["total_s"] = time.perf_counter() - t0
    result = Detection(scores, tracks, best_rollouts, models, timings, settings)
    if settings.labels is not None:
        result.metrics = evaluate_labels(result, settings.labels)
    return result


# ----------------------------------------------------------------------------------- outputs
def _line(coords: np.ndarray) -> dict[str, Any]:
    return {"type": "LineString", "coordinates": np.round(coords, 6).tolist()}


def anomalies_geojson(result: Detection) -> dict[str, Any]:
    """Flagged tracks (kind=track), their nearest rollouts (kind=rollout) and the points of
    largest deviation (kind=max_deviation), as one FeatureCollection in lon/lat (WGS84)."""
    features = []
    by_id = {t.track_id: (t, r) for t, r in zip(result.tracks, result.rollouts, strict=True)}
    for row in result.scores[result.scores["flagged"]].sort_values("rank").itertuples():
        track, roll = by_id[row.track_id]
        props = {
            "track_id": int(row.track_id),
            "mmsi": int(row.mmsi),
            "model": row.model,
            "rank": int(row.rank),
            "score": float(row.score),
            "score_m": float(row.score_m),
            "max_dev_m": float(row.max_dev_m),
            "start": str(track.start),
        }
        features.append(
            {
                "type": "Feature",
                "properties": {"kind": "track", **props},
                "geometry": _line(track.positions),
            }
        )
        features.append(
            {
                "type": "Feature",
                "properties": {"kind": "rollout", "track_id": props["track_id"]},
                "geometry": _line(roll),
            }
        )
        point = {
            "type": "Point",
            "coordinates": [round(row.max_dev_lon, 6), round(row.max_dev_lat, 6)],
        }
        features.append(
            {
                "type": "Feature",
                "properties": {
                    "kind": "max_deviation",
                    "track_id": props["track_id"],
                    "distance_m": props["max_dev_m"],
                },
                "geometry": point,
            }
        )
    return {"type": "FeatureCollection", "features": features}


def write_outputs(result: Detection, out: Path) -> list[Path]:
    from aisdati.plots import html_detection_map, plot_detection_map

    out.mkdir(parents=True, exist_ok=True)
    files = []
    table = pa.Table.from_pandas(
        result.scores.sort_values("rank").reset_index(drop=True),
        schema=SCORES_SCHEMA,
        preserve_index=False,
    )
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    path = out / "scores.parquet"
    atomic_write_bytes(path, sink.getvalue().to_pybytes())
    files.append(path)
    path = out / "anomalies.geojson"
    atomic_write_bytes(path, json.dumps(anomalies_geojson(result)).encode())
    files.append(path)
    path = out / "map.png"
    flagged = result.scores["flagged"].to_numpy()
    plot_detection_map(
        [t.positions for t in result.tracks],
        result.rollouts,
        flagged,
        result.scores[["max_dev_lon", "max_dev_lat"]].to_numpy(),
        [m.bounds for m in result.models],
        path,
        title=_map_title(result),
    )
    files.append(path)
    path = out / "map.html"
    html_detection_map(
        [t.positions for t in result.tracks],
        result.rollouts,
        [_track_props(r) for r in result.scores.itertuples()],
        flagged,
        [m.bounds for m in result.models],
        path,
    )
    files.append(path)
    if result.metrics is not None:
        path = out / "metrics.json"
        atomic_write_bytes(path, json.dumps(result.metrics, indent=2).encode())
        files.append(path)
    path = out / "report.json"
    atomic_write_bytes(path, json.dumps(report_dict(result), indent=2, default=str).encode())
    files.append(path)
    return files


def _track_props(row: Any) -> dict[str, Any]:
    return {
        "track_id": int(row.track_id),
        "mmsi": int(row.mmsi),
        "rank": int(row.rank),
        "score": round(float(row.score), 4),
        "score_m": round(float(row.score_m), 1),
        "max_dev_m": round(float(row.max_dev_m), 1),
        "max_dev_lon": float(row.max_dev_lon),
        "max_dev_lat": float(row.max_dev_lat),
    }


def _map_title(result: Detection) -> str:
    s = result.settings
    n, f = len(result.scores), int(result.scores["flagged"].sum())
    rule = f"top {s.top_percent:g}%" if s and s.top_percent else f"score > {s.threshold:g}"
    return f"DATI anomalies: {f} of {n} test tracks flagged ({rule})"


def report_dict(result: Detection) -> dict[str, Any]:
    s = result.settings
    sc = result.scores
    return {
        "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in s.__dict__.items()}
        if s
        else {},
        "models": [m.name for m in result.models],
        "warnings": [w for m in result.models for w in m.warnings],
        "test_tracks": len(sc),
        "flagged": int(sc["flagged"].sum()),
        "max_score_m": float(sc["score_m"].max()) if len(sc) else None,
        "timings": {k: round(v, 3) for k, v in result.timings.items()},
        "metrics": result.metrics,
        "score_definition": "best of K rollouts of great-circle DTW / warping-path length (m), "
        "divided by the maximum over the test set",
    }


# ------------------------------------------------------------------------------------ labels
def read_labels(path: Path) -> pd.DataFrame:
    """A CSV with `label` (0/1) and either `track_id` or `mmsi` + `start` (UTC time of the
    track's first report; matched within 60 s). Every value is checked here, before any work, and
    the first bad one is named with its row: ids must be integers (track ids >= 0 and within
    int64, MMSIs positive), starts times, labels 0 or 1, and one key may not get two labels."""
    if not path.is_file():
        raise UserError(f"labels file not found: {path}")
    try:
        raw = pd.read_csv(path, dtype=str, keep_default_na=False, encoding="utf-8")
    except (ValueError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read labels {path}: {str(exc).splitlines()[0]}") from None
    raw.columns = [str(c).strip().lower() for c in raw.columns]
    if "label" not in raw:
        raise UserError(f"{path}: no 'label' column (expected track_id,label or mmsi,start,label)")
    if "track_id" not in raw and not {"mmsi", "start"} <= set(raw):
        raise UserError(f"{path}: needs a 'track_id' column, or 'mmsi' and 'start' columns")
    if raw.empty:
        raise UserError(f"{path}: the file holds no labels")
    labels = pd.DataFrame(index=raw.index)
    keys = ["track_id"] if "track_id" in raw else ["mmsi", "start"]
    if "track_id" in raw:
        labels["track_id"] = _label_ints(raw["track_id"], "track_id", 0, 2**63 - 1, path)
    else:
        labels["mmsi"] = _label_ints(raw["mmsi"], "mmsi", 1, 2**53, path)
        start = pd.to_datetime(raw["start"].str.strip(), utc=True, errors="coerce", format="mixed")
        if start.isna().any():
            row = int(np.flatnonzero(start.isna().to_numpy())[0])
            raise UserError(
                f"{path}: row {row + 1}: start must be a time (ISO 8601, UTC), "
                f"got {_shown(raw['start'].iloc[row])}"
            )
        labels["start"] = start
    text = raw["label"].str.strip()
    bad = ~text.isin(["0", "1", "0.0", "1.0"])
    if bad.any():
        row = int(np.flatnonzero(bad.to_numpy())[0])
        raise UserError(
            f"{path}: row {row + 1}: label must be 0 or 1, got {_shown(raw['label'].iloc[row])}"
        )
    labels["label"] = text.str[0].astype(int)
    conflict = labels.groupby(keys)["label"].nunique() > 1
    if conflict.any():
        key = conflict.index[np.flatnonzero(conflict.to_numpy())[0]]
        raise UserError(f"{path}: {'/'.join(keys)} {key} has both labels 0 and 1")
    return labels


def _shown(value: Any) -> str:
    text = repr(str(value))
    return text if len(text) <= 40 else text[:37] + "..."


def _label_ints(values: pd.Series, column: str, low: int, high: int, path: Path) -> pd.Series:
    """A column of integer ids (written as 12 or 12.0) within [low, high], or a `UserError`
    naming the first row that is not one."""
    out = np.zeros(len(values), dtype=np.int64)
    for row, value in enumerate(values.to_numpy()):
        match = re.fullmatch(r"\s*\+?(\d{1,30})(?:\.0*)?\s*", value)
        number = int(match[1]) if match else None
        if number is None or not low <= number <= high:
            raise UserError(
                f"{path}: row {row + 1}: {column} must be an integer in [{low}, {high}], "
                f"got {_shown(value)}"
            )
        out[row] = number
    return pd.Series(out, index=values.index)


def match_labels(scores: pd.DataFrame, tracks: Sequence[Track], labels: pd.DataFrame) -> np.ndarray:
    """The label of every scored track, -1 where it has none."""
    out = np.full(len(scores), -1)
    if "track_id" in labels:
        lab = dict(zip(labels["track_id"].astype(int), labels["label"], strict=True))
        out = np.array([lab.get(int(t), -1) for t in scores["track_id"]])
    else:
        starts = pd.to_datetime(labels["start"], utc=True, errors="coerce")
        by_mmsi: dict[int, list[tuple[pd.Timestamp, int]]] = {}
        for m, s, v in zip(labels["mmsi"].astype(int), starts, labels["label"], strict=True):
            if pd.notna(s):
                by_mmsi.setdefault(m, []).append((s, int(v)))
        start_of = {t.track_id: pd.Timestamp(t.start) for t in tracks}
        for i, (tid, mmsi) in enumerate(zip(scores["track_id"], scores["mmsi"], strict=True)):
            st = start_of[int(tid)]
            st = st.tz_localize("UTC") if st.tzinfo is None else st
            for s, v in by_mmsi.get(int(mmsi), []):
                if abs((s - st).total_seconds()) <= 60:
                    out[i] = v
    if not (out >= 0).any():
        raise UserError("the labels match no test track (check track_id, or mmsi and start)")
    return out


def roc_auc(y: np.ndarray, s: np.ndarray) -> float | None:
    """Area under the ROC curve (Mann-Whitney U with average ranks for ties)."""
    from scipy.stats import rankdata

    pos, neg = int(y.sum()), int(len(y) - y.sum())
    if pos == 0 or neg == 0:
        return None
    ranks = rankdata(s)
    return float((ranks[y == 1].sum() - pos * (pos + 1) / 2) / (pos * neg))


def label_metrics(y: np.ndarray, flagged: np.ndarray, score: np.ndarray) -> dict[str, Any]:
    """Precision and recall of the anomaly class, weighted F1 (the paper's metric: per-class F1
    weighted by class support) and ROC AUC of the normalised score."""
    y, p = np.asarray(y, int), np.asarray(flagged, int)

    def prf(c: int) -> tuple[float, float, float]:
        tp = int(((p == c) & (y == c)).sum())
        prec = tp / max(int((p == c).sum()), 1)
        rec = tp / max(int((y == c).sum()), 1)
        f1 = 2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0
        return prec, rec, f1

    p1, r1, _ = prf(1)
    support = np.array([(y == 0).sum(), (y == 1).sum()], dtype=float)
    f1s = np.array([prf(0)[2], prf(1)[2]])
    return {
        "labelled_tracks": len(y),
        "anomalies_labelled": int(y.sum()),
        "flagged": int(p.sum()),
        "precision": p1,
        "recall": r1,
        "f1_weighted": float((support * f1s).sum() / support.sum()),
        "roc_auc": roc_auc(y, score),
    }


def evaluate_labels(result: Detection, path: Path) -> dict[str, Any]:
    labels = read_labels(path)
    matched = match_labels(result.scores, result.tracks, labels)
    keep = matched >= 0
    metrics = label_metrics(
        matched[keep], result.scores["flagged"].to_numpy()[keep], result.scores["score"][keep]
    )
    metrics["labels_file"] = str(path)
    metrics["labels_unmatched"] = int(len(labels) - keep.sum())
    return metrics
