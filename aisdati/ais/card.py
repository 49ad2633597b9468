"""The AIS model card (`<cluster>.json` beside `<cluster>.pt`), validated as a whole before use.

A card edited by hand or damaged can hold a negative or NaN speed range, an inverted region,
start points in the sea of NaN: the networks still load and `detect` would run and flag other
tracks than the model would. So every field `detect` reads is checked for its type, finiteness
and range, and the first bad one is named in a one-line `UserError`:
`model card models/up.json: rule.max_sog_kn must be a finite number > 0, got -3`.

Also here: which of a data set's tracks a model was trained on (`training_mask`), by a key that
survives re-ingesting (vessel and time span), and the warnings a usable card can still deserve
(`card_warnings`: training that never finished).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aisdati.ais.space import MAX_FOURIER, MAX_MEMBERS, MAX_PRETRAIN, state_width
from aisdati.errors import UserError

MAX_MMSI = 2**53
_MISSING = object()


class _Card:
    """Typed access to a card's fields by dotted path; every failure is one named `UserError`."""

    def __init__(self, doc: Any, path: Path | str) -> None:
        self.doc = doc
        self.path = path

    def fail(self, field: str, rule: str, value: Any, shown: str | None = None) -> UserError:
        got = _show(value) if shown is None else shown
        return UserError(f"model card {self.path}: {field} must be {rule}, got {got}")

    def get(self, field: str, default: Any = _MISSING) -> Any:
        node = self.doc
        for part in field.split("."):
            if not isinstance(node, dict) or part not in node:
                if default is not _MISSING:
                    return default
                raise UserError(f"model card {self.path}: {field} is missing")
            node = node[part]
        return node

    def number(
        self,
        field: str,
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
        value: Any = _MISSING,
    ) -> float:
        v = self.get(field) if value is _MISSING else value
        rule = _rule(low, high, low_open)
        if not _is_number(v) or not math.isfinite(v):
            raise self.fail(field, f"a finite number{rule}", v)
        if low is not None and (v <= low if low_open else v < low):
            raise self.fail(field, f"a finite number{rule}", v)
        if high is not None and v > high:
            raise self.fail(field, f"a finite number{rule}", v)
        return float(v)

    def integer(
        self, field: str, low: int | None = None, high: int | None = None, value: Any = _MISSING
    ) -> int:
        v = self.get(field) if value is _MISSING else value
        if not isinstance(v, int) or isinstance(v, bool):
            raise self.fail(field, f"an integer{_rule(low, high)}", v)
        if (low is not None and v < low) or (high is not None and v > high):
            raise self.fail(field, f"an integer{_rule(low, high)}", v)
        return v

    def choice(self, field: str, allowed: Sequence[Any]) -> Any:
        v = self.get(field)
        if isinstance(v, bool) or v not in allowed:
            raise self.fail(field, "one of " + ", ".join(map(_show, allowed)), v)
        return v

    def boolean(self, field: str, default: Any = _MISSING) -> Any:
        v = self.get(field, default)
        if v is not default and not isinstance(v, bool):
            raise self.fail(field, "true or false", v)
        return v

    def text(self, field: str) -> str:
        v = self.get(field)
        if not isinstance(v, str) or not v.strip():
            raise self.fail(field, "a non-empty string", v)
        return v

    def array(self, field: str, length: int | None = None, min_length: int = 0) -> list[Any]:
        v = self.get(field)
        if not isinstance(v, list):
            raise self.fail(field, "a list", v)
        if length is not None and len(v) != length:
            raise self.fail(field, f"a list of {length}", v, f"{len(v)} items")
        if len(v) < min_length:
            raise self.fail(field, f"a list of at least {min_length}", v, f"{len(v)} items")
        return v

    def interval(self, field: str, low: float, high: float) -> tuple[float, float]:
        pair = self.array(field, length=2)
        lo = self.number(f"{field}[0]", low, high, value=pair[0])
        hi = self.number(f"{field}[1]", low, high, value=pair[1])
        if not lo < hi:
            raise self.fail(field, "[low, high] with low < high", pair)
        return lo, hi


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _rule(low: float | None, high: float | None, low_open: bool = False) -> str:
    if low is not None and high is not None:
        return f" in {'(' if low_open else '['}{_num(low)}, {_num(high)}]"
    if low is not None:
        return f" {'>' if low_open else '>='} {_num(low)}"
    if high is not None:
        return f" <= {_num(high)}"
    return ""


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"


def _show(value: Any) -> str:
    """A value as the error message shows it: short, one line, no raw control characters."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)  # nan, inf, -inf
    if _is_number(value):
        return _num(value)
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def validate_ais_card(doc: Any, path: Path | str) -> dict[str, Any]:
    """Check an AIS model card as a whole (what loading a detector and `detect` rely on) and
    return it; the first field out of type, range or finiteness raises a one-line `UserError`.
    Every detector's card (dati, bc, nearest) shares the data, region, rule and lane fields;
    DATI's and BC's add their networks' settings."""
    card = _Card(doc, path)
    if not isinstance(doc, dict):
        raise UserError(f"model card {path}: expected a JSON object, got {type(doc).__name__}")
    if doc.get("kind") != "ais":
        raise UserError(f"{path} is not an AIS model card (train one with `aisdati train`)")
    fmt = doc.get("format")
    card.text("cluster")
    card.integer("seed")

    # the update rule and the region it sticks to
    card.number("rule.max_sog_kn", 0.0, 1000.0, low_open=True)
    card.number("rule.max_dt_h", 0.0, 24.0 * 366, low_open=True)
    if card.get("rule.cog_center_deg", None) is not None:
        card.number("rule.cog_center_deg", -360.0, 360.0)
    card.interval("region.lon", -360.0, 360.0)
    card.interval("region.lat", -91.0, 91.0)
    lane = card.get("lane_config", None)
    if lane is not None:
        if not isinstance(lane, dict):
            raise card.fail("lane_config", "an object", lane)
        if "corridor_km" in lane:
            card.number("lane_config.corridor_km", 0.0, 1000.0, low_open=True)
        for key in ("validation_tracks", "validation_rollouts"):
            if key in lane:
                card.integer(f"lane_config.{key}", 1)
        for key, most in (("fourier", MAX_FOURIER), ("pretrain", MAX_PRETRAIN)):
            if key in lane:
                card.integer(f"lane_config.{key}", 0, most)

    # the networks
    if fmt in ("aisdati-dati/1", "aisdati-bc/1"):
        has = isinstance(lane, dict) and "members" in lane  # older cards: one member
        members = card.integer("lane_config.members", 1, MAX_MEMBERS) if has else 1
        seeds = card.array("seeds", length=members)
        for i, seed in enumerate(seeds):
            card.integer(f"seeds[{i}]", value=seed)
    if fmt == "aisdati-dati/1":
        view = lane if isinstance(lane, dict) else {}
        card.choice("state_dim", (state_width(view.get("state", ""), view.get("fourier", 0)),))
        card.integer("decision_dim", 3, 3)
        card.choice("config.noise", ("gaussian", "ou"))
        card.number("config.noise_sigma", 0.0, 100.0)
        card.number("config.ou_theta", 0.0, 100.0)
        card.number("config.ou_dt", 0.0, 100.0, low_open=True)
        card.integer("config.network.latent_dim", 1)
        card.number("epsilon_m", 0.0, low_open=True)
    elif fmt == "aisdati-bc/1":
        config = card.get("config")
        if not isinstance(config, dict):
            raise card.fail("config", "an object", config)
        for key, value in config.items():
            if _is_number(value):
                card.number(f"config.{key}", value=value)

    # the training data: ids, starts and (since 0.1.0) stable keys
    ids = card.array("data.track_ids", min_length=1)
    for i, v in enumerate(ids):
        card.integer(f"data.track_ids[{i}]", 0, value=v)
    card.integer("data.points", len(ids))  # the traffic's rollouts run their mean length
    starts = card.array("data.start_points", length=len(ids))
    for i, point in enumerate(starts):
        field = f"data.start_points[{i}]"
        if not isinstance(point, list) or len(point) != 2:
            raise card.fail(field, "a [lon, lat] pair", point)
        card.number(f"{field}[0]", -180.0, 180.0, value=point[0])
        card.number(f"{field}[1]", -90.0, 90.0, value=point[1])
    keys = card.get("data.track_keys", None)
    if keys is not None:
        card.array("data.track_keys", length=len(ids))
        parse_track_keys(keys, card)

    # scores of the training tracks, which thresholds and `--score both` divide by
    calibration = card.get("calibration", None)
    if calibration is not None:
        if not isinstance(calibration, dict):
            raise card.fail("calibration", "an object", calibration)
        for key, values in calibration.items():
            card.array(f"calibration.{key}", min_length=1)
            for i, v in enumerate(values):
                card.number(f"calibration.{key}[{i}]", 0.0, value=v)
    calibrated_with = card.get("calibrated_with", None)  # the scoring settings of calibration
    if calibrated_with is not None:
        if not isinstance(calibrated_with, dict):
            raise card.fail("calibrated_with", "an object", calibrated_with)
        if "lane_course_km" in calibrated_with:  # older cards: position only
            card.number("calibrated_with.lane_course_km", 0.0, 1000.0)
        if "lane_traffic" in calibrated_with:  # older cards: without the traffic rollouts
            card.boolean("calibrated_with.lane_traffic", None)

    # training state: `detect` warns about a model whose training did not finish
    card.boolean("training.finished", None)
    if card.get("training.episodes_run", None) is not None:
        card.integer("training.episodes_run", 0)
    return doc


def parse_track_keys(keys: Sequence[Any], card: _Card | None = None) -> pd.DataFrame:
    """`data.track_keys` ([mmsi, "start", "end"] per training track; "end" may be missing) as a
    frame of mmsi, start and end (UTC)."""
    card = card or _Card({}, "?")
    mmsi, start, end = [], [], []
    for i, key in enumerate(keys):
        field = f"data.track_keys[{i}]"
        if not isinstance(key, list) or len(key) not in (2, 3):
            raise card.fail(field, '[mmsi, "start", "end"]', key)
        mmsi.append(card.integer(f"{field}[0]", 1, MAX_MMSI, value=key[0]))
        times = []
        for j, text in enumerate(key[1:], start=1):
            ok = isinstance(text, str)
            stamp = pd.to_datetime(text, utc=True, errors="coerce") if ok else None
            if stamp is None or pd.isna(stamp):
                raise card.fail(f"{field}[{j}]", "an ISO 8601 time", text)
            times.append(stamp)
        if len(times) == 2 and times[1] < times[0]:
            raise card.fail(field, "a start before its end", key)
        start.append(times[0])
        end.append(times[-1])
    return pd.DataFrame(
        {"mmsi": np.asarray(mmsi, np.int64), "start": pd.DatetimeIndex(start, tz="UTC"),
         "end": pd.DatetimeIndex(end, tz="UTC")}
    )  # fmt: skip


def track_keys(tracks: pd.DataFrame) -> list[list[Any]]:
    """The stable key of each track of a tracks.parquet frame: [mmsi, start, end] (ISO 8601, UTC).
    Track ids are numbered by ingest and change when the data is ingested again with other
    settings; a vessel's time span does not."""
    return [
        [int(m), _iso(s), _iso(e)]
        for m, s, e in zip(tracks["mmsi"], tracks["start"], tracks["end"], strict=True)
    ]


def _iso(stamp: Any) -> str:
    ts = pd.Timestamp(stamp)
    ts = ts.tz_localize("UTC") if ts.tzinfo is None else ts.tz_convert("UTC")
    return ts.isoformat()


def training_mask(card: dict[str, Any], tracks: pd.DataFrame) -> np.ndarray:
    """Which rows of a tracks.parquet frame (track_id, mmsi, start, end) are the model's training
    tracks. With `data.track_keys`: the same vessel over an overlapping time span (so re-ingesting
    with other settings, which renumbers tracks and may move a track's ends by a few reports,
    still finds them). Older cards without keys: by track id, as they were written."""
    keys = card["data"].get("track_keys")
    if keys is None:
        ids = {int(i) for i in card["data"]["track_ids"]}
        return np.isin(tracks["track_id"].to_numpy(), list(ids))
    trained = parse_track_keys(keys)
    mask = np.zeros(len(tracks), dtype=bool)
    if trained.empty or tracks.empty:
        return mask
    start = pd.to_datetime(tracks["start"], utc=True).to_numpy()
    end = pd.to_datetime(tracks["end"], utc=True).to_numpy()
    mmsi = tracks["mmsi"].to_numpy(np.int64)
    for m, group in trained.groupby("mmsi"):
        rows = np.flatnonzero(mmsi == m)
        if not rows.size:
            continue
        t0 = group["start"].to_numpy()
        t1 = group["end"].to_numpy()
        overlap = (start[rows, None] <= t1[None, :]) & (end[rows, None] >= t0[None, :])
        mask[rows[overlap.any(axis=1)]] = True
    return mask


def card_warnings(card: dict[str, Any], name: str) -> list[str]:
    """What an operator should know before trusting a valid card's model."""
    warnings = []
    tr = card.get("training")
    if isinstance(tr, dict) and tr.get("finished") is False:
        warnings.append(
            f"model {name}: training did not finish (stopped after {tr.get('episodes_run')} of "
            f"{tr.get('episodes_max')} episodes), so its scores come from a partly trained model; "
            "finish it with `aisdati train --resume`"
        )
    return warnings


def unfinished_models(
    models_dir: Path, names: Sequence[str], method: str | None = None
) -> list[str]:
    """`card_warnings` of the models `detect` is about to load (the named ones, or every model of
    `method` in the folder), read from their cards alone so that they are shown before any work.
    Cards that cannot be read are skipped here: loading them gives the error."""
    if names:
        stems = [models_dir / n for n in names]
    else:
        stems = sorted(p.with_suffix("") for p in models_dir.glob("*.json"))
    warnings = []
    for stem in stems:
        try:
            doc = json.loads(stem.with_suffix(".json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if not isinstance(doc, dict) or doc.get("kind") != "ais":
            continue
        if not names and method and not str(doc.get("format", "")).startswith(f"aisdati-{method}/"):
            continue
        warnings += card_warnings(doc, stem.name)
    return warnings
