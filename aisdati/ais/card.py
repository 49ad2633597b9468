"""The AIS model card (`<stem>.json` beside a detector's weights or tracks) as one typed object.

`ModelCard` is what every detector (dati, bc, nearest) knows about itself besides its networks
or remembered tracks: the data it was trained on, the region and update rule it moves in, the
lane configuration, how training went and the scores its threshold is calibrated on. Code reads
and edits the card's fields; only `to_dict` and `from_dict` know the JSON.

A card edited by hand or damaged can hold a negative or NaN speed range, an inverted region,
start points in the sea of NaN: the networks still load and `detect` would run and flag other
tracks than the model would. So `from_dict` checks every field `detect` reads for its type,
finiteness and range, and names the first bad one in a one-line `UserError`:
`model card models/up.json: rule.max_sog_kn must be a finite number in (0, 1000], got -3`.
Every count has an upper bound too (`MAX_TRACKS`, `MAX_POINTS`, ...: what the largest real
model could hold), since counts size what is built from the card: `data.points: 1e12` asked the
traffic rollouts for terabytes. `read_card` reads the file itself within a size and a nesting
depth (`aisdati.model.readers.read_json`).

Also here: which of a data set's tracks a model was trained on (`training_mask`), by a key that
survives re-ingesting (vessel and time span), and the warnings a usable card can still deserve
(`card_warnings`: training that never finished).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aisdati.ais import LAST_RELEASE_WITH_EXPERIMENTS
from aisdati.ais.card_fields import CardFields, is_number
from aisdati.ais.corridor import Corridor
from aisdati.ais.space import (
    MAX_FOURIER,
    MAX_MEMBERS,
    MAX_PRETRAIN,
    AISSpace,
    LaneConfig,
    state_width,
)
from aisdati.errors import UserError
from aisdati.model.persistence import MAX_LAYERS, MAX_UNITS, NETWORKS_FORMAT
from aisdati.model.readers import read_json
from aisdati.model.rules import SphericalRule
from aisdati.outdir import atomic_write_bytes
from aisdati.scores import REMOVED_SCORES, SCORES
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import Track

CARD_FORMATS: dict[str, str] = {
    "dati": NETWORKS_FORMAT,  # DATI's card is the one its networks are saved with
    "bc": "aisdati-bc/1",
    "nearest": "aisdati-nearest/1",
}
"""Each detector's card format (the card's `format`), by method: the one place card versions
are written."""
KIND = "ais"
MAX_MMSI = 2**53
MAX_COUNT = 2**53
"""Counts that size nothing (shown only): any integer JSON holds exactly."""
MAX_SEED = 2**63 - 1
"""torch's generators take 64-bit seeds (a lane's members: the run's seed + 1000 k)."""
MAX_TRACKS = 100_000
"""Training tracks of one model: DATI trains one episode per track (the paper: 170), and
`nearest` compares a track with every training track that starts near it."""
MAX_TRACK_POINTS = 100_000
"""Mean reports per training track: 55 hours at one report every 2 s. DATI's reward DTW costs
O(n) per step, O(n²) per episode; the lane score's traffic rollouts run this many steps."""
MAX_POINTS = 50_000_000
"""All training reports: `nearest` keeps them in memory (16 bytes each, 0.8 GB), a lane's
traffic rollouts take 32 bytes per report."""
MAX_EPISODES = 1_000_000
"""Training episodes (the paper: 170): a million episodes of the shortest track take weeks."""
MAX_VALIDATION_ROLLOUTS = 1000
"""Rollouts per validation track (the lanes preset: 3)."""
MAX_DRAWS = 1000
"""Most rollouts or one-step draws per track a card may record its calibration with."""
RULE_NAME = "spherical (eq. 5)"
RULE_DECISIONS = ("sog_kn", "cog_deg", "dt_h")


def card_method(fmt: Any) -> str | None:
    """The method a card `format` belongs to (None: not an aisdati detector's card)."""
    return next((m for m, f in CARD_FORMATS.items() if f == fmt), None)


# ---------------------------------------------------------------------------------- sections
@dataclass(frozen=True)
class Region:
    """The lon/lat box the agent is kept in (the training tracks' box with a margin)."""

    lon: tuple[float, float]
    lat: tuple[float, float]

    @classmethod
    def from_bounds(cls, bounds: tuple[np.ndarray, np.ndarray]) -> Region:
        lo, hi = bounds
        return cls((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])))

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) as (lon, lat) arrays."""
        return (
            np.array([self.lon[0], self.lat[0]], np.float64),
            np.array([self.lon[1], self.lat[1]], np.float64),
        )

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Whether each [lon, lat] point lies in the box."""
        lo, hi = self.bounds
        return np.all((points >= lo) & (points <= hi), axis=-1)

    def to_dict(self) -> dict[str, Any]:
        return {"lon": list(self.lon), "lat": list(self.lat)}


@dataclass(frozen=True)
class RuleCard:
    """The decision ranges of the spherical update rule (eq. 5)."""

    max_sog_kn: float
    max_dt_h: float
    cog_center_deg: float | None = None
    """The centre of the COG window; None in cards from before it (then 180)."""

    @classmethod
    def from_rule(cls, rule: SphericalRule) -> RuleCard:
        return cls(rule.max_sog, rule.max_dt_h, rule.cog_center)

    def to_rule(self) -> SphericalRule:
        center = 180.0 if self.cog_center_deg is None else float(self.cog_center_deg)
        return SphericalRule(
            max_sog=float(self.max_sog_kn), max_dt_h=float(self.max_dt_h), cog_center=center
        )

    def to_dict(self) -> dict[str, Any]:
        doc = {"name": RULE_NAME, "decisions": list(RULE_DECISIONS)}
        doc |= {"max_sog_kn": self.max_sog_kn, "max_dt_h": self.max_dt_h}
        return doc if self.cog_center_deg is None else doc | {"cog_center_deg": self.cog_center_deg}


@dataclass(kw_only=True)
class DataCard:
    """The training tracks: their ids and stable keys, sizes, start points and where they came
    from (`dir`, `files`, `cluster`, `tracks_in_cluster`: what training from an ingest folder
    records; None when fitted on tracks in memory)."""

    track_ids: list[int]
    points: int
    """All their reports; the traffic rollouts of a lane run their mean length."""
    start_points: list[list[float]]
    """[lon, lat] of each track's first report."""
    end_points: list[list[float]] | None = None
    """[lon, lat] of each track's last report (where it was bound: routing reads it); None in
    cards before 0.2.0."""
    ashore_points: list[list[float]] | None = None
    """[lon, lat] where the tracks reported ashore by the coastline: water it misses (creeks,
    rivers), which the ashore rule then excuses (`aisdati.tracks.ashore`); None in cards written
    before the rule (it then excuses nothing)."""
    track_keys: list[list[Any]] | None = None
    """[mmsi, "start", "end"] per track (ISO 8601, UTC; `track_keys`); None in cards before
    0.1.0, which `training_mask` matches by id."""
    dir: str | None = None
    files: list[str] | None = None
    cluster: str | None = None
    tracks_in_cluster: int | None = None
    tracks_used: int | None = None
    time_span: list[str] | None = None

    @property
    def starts(self) -> np.ndarray:
        """[n, 2] `start_points` as an array."""
        return np.asarray(self.start_points, np.float64).reshape(-1, 2)

    @property
    def ends(self) -> np.ndarray | None:
        """[n, 2] `end_points` as an array; None in cards from before they were recorded."""
        ends = self.end_points
        return None if ends is None else np.asarray(ends, np.float64).reshape(-1, 2)

    @property
    def ashore(self) -> np.ndarray:
        """[m, 2] `ashore_points` as an array (none for a card from before the rule)."""
        return np.asarray(self.ashore_points or [], np.float64).reshape(-1, 2)

    @classmethod
    def of_tracks(
        cls, tracks: Sequence[Track], spans: pd.DataFrame | None = None, **source: Any
    ) -> DataCard:
        """The card of `tracks`. `spans`: their rows of tracks.parquet (mmsi, start, end), in
        their order; without it, each track's span is its first report plus its time steps.
        `source`: where they came from (dir, files, cluster, tracks_in_cluster)."""
        if spans is None:
            start = [pd.Timestamp(t.start) for t in tracks]
            hours = [float(t.dts.sum()) for t in tracks]
            end = [s + pd.to_timedelta(h, "h") for s, h in zip(start, hours, strict=True)]
            spans = pd.DataFrame({"mmsi": [t.mmsi for t in tracks], "start": start, "end": end})
        return cls(
            tracks_used=len(tracks),
            track_ids=[t.track_id for t in tracks],
            track_keys=track_keys(spans),
            points=int(sum(len(t.positions) for t in tracks)),
            time_span=[str(spans["start"].min()), str(spans["end"].max())],
            start_points=[[float(t.positions[0, 0]), float(t.positions[0, 1])] for t in tracks],
            end_points=[[float(t.positions[-1, 0]), float(t.positions[-1, 1])] for t in tracks],
            ashore_points=AshoreCheck().seen([t.positions for t in tracks]),
            **source,
        )

    def to_dict(self) -> dict[str, Any]:
        order = ("dir", "files", "cluster", "tracks_in_cluster", "tracks_used", "track_ids",
                 "track_keys", "points", "time_span", "start_points", "end_points",
                 "ashore_points")  # fmt: skip
        return _present({k: getattr(self, k) for k in order})


@dataclass(kw_only=True)
class TrainingReport:
    """How training went. `detect` warns about a model whose training did not `finish`; the
    rest of the method's record (DATI's curves per member, BC's final loss) is `details`."""

    episodes_run: int | None = None
    episodes_max: int | None = None
    wall_seconds: float | None = None
    finished: bool | None = None
    routes_in_ensemble: int | None = None
    """Routes trained as one batched ensemble with this one (absent: trained alone)."""
    details: dict[str, Any] = field(default_factory=dict)

    TYPED = ("episodes_run", "episodes_max", "wall_seconds", "finished", "routes_in_ensemble")

    def to_dict(self) -> dict[str, Any]:
        typed = _present({k: getattr(self, k) for k in self.TYPED})
        first = {k: typed.pop(k) for k in ("episodes_run",) if k in typed}
        return {**first, **self.details, **typed}


@dataclass(frozen=True)
class CalibratedWith:
    """The scoring settings a card's calibration scores were computed with
    (`ScoreSettings.calibrated_with`): a threshold needs the same. The defaults are what cards
    that do not record a setting were calibrated with."""

    lane_course_km: float = 0.0
    lane_traffic: bool = False
    rollouts: int = 10
    """K: rollouts and one-step draws per track (cards before it: the CLI's 10)."""
    lane_rollouts: int = 30
    """Rollouts that make up a track's lane (cards before it: the CLI's 30)."""
    reported_motion: bool = False
    """Whether the step scores also judged where the reported motion puts the vessel (cards
    before it: the positions only)."""


@dataclass(kw_only=True)
class NetworkCard:
    """A learnt detector's networks: one seed per ensemble member and their hyperparameters
    (`DATIConfig.to_dict()` or `BCConfig.to_dict()`); DATI's also record their widths."""

    seeds: list[int]
    config: dict[str, Any]
    state_dim: int | None = None
    decision_dim: int | None = None

    def to_dict(self) -> dict[str, Any]:
        widths = _present({"state_dim": self.state_dim, "decision_dim": self.decision_dim})
        return {**widths, "config": self.config, "seeds": self.seeds}


# ------------------------------------------------------------------------------------ the card
@dataclass(kw_only=True)
class ModelCard:
    """Everything a saved detector says about itself; see the module docstring."""

    method: str
    """dati, bc or nearest (the card's `format`, `CARD_FORMATS`)."""
    cluster: str
    seed: int
    data: DataCard
    region: Region
    rule: RuleCard
    lane_config: LaneConfig = field(default_factory=LaneConfig)
    """The lane configuration (cards from before them: the paper's, `LaneConfig()`)."""
    preset: str | None = None
    """The name of the preset `lane_config` came from (with any overrides)."""
    score: str = "lane"
    """The score the model judges by where `--score` is not given: its preset's when it was
    trained (`aisdati.ais.space.PRESET_SCORES`); cards from before this field: lane, the score
    they were measured with."""
    created: str | None = None
    code_version: str | None = None
    training: TrainingReport = field(default_factory=TrainingReport)
    calibration: dict[str, list[float]] = field(default_factory=dict)
    """The training tracks' own scores by kind (rollout, step, lane, both; nearest): what
    thresholds and `--score both` divide by. Empty until calibrated."""
    calibrated_with: CalibratedWith | None = None
    networks: NetworkCard | None = None
    """dati and bc; None for nearest, which remembers tracks."""
    epsilon_m: float | None = None
    """DATI's ε (metres) and how it is compared with the DTW (`epsilon_interpretation`)."""
    epsilon_interpretation: str | None = None
    files: dict[str, str] | None = None
    """The SHA-256 of each file of the model beside the card, by suffix (`.pt`,
    `.corridor.npz`, `.npz`): a model whose files do not match (an interrupted retraining into a
    folder that held another) refuses to load (`check_files`). None in cards before it."""

    @property
    def format(self) -> str:
        return CARD_FORMATS[self.method]

    def space(self, corridor: Corridor | None = None) -> AISSpace:
        """The space the saved model moves in (its corridor is saved beside it)."""
        return AISSpace(self.region.bounds, self.rule.to_rule(), self.lane_config, corridor)

    def to_dict(self) -> dict[str, Any]:
        """The card as JSON-ready dicts and lists (what `<stem>.json` holds)."""
        doc = {"format": self.format, "method": self.method, "kind": KIND, "cluster": self.cluster,
               "created": self.created, "code_version": self.code_version, "seed": self.seed,
               "data": self.data.to_dict(), "preset": self.preset, "score": self.score,
               "region": self.region.to_dict(), "rule": self.rule.to_dict(),
               "lane_config": self.lane_config.to_dict(), "epsilon_m": self.epsilon_m,
               "epsilon_interpretation": self.epsilon_interpretation,
               "training": self.training.to_dict() or None, "calibration": self.calibration or None,
               "calibrated_with": asdict(self.calibrated_with) if self.calibrated_with else None,
               "files": self.files,
               }  # fmt: skip
        return _present(doc) | (self.networks.to_dict() if self.networks else {})

    @classmethod
    def from_dict(cls, doc: Any, path: Path | str) -> ModelCard:
        """Read and check a card as a whole (what loading a detector and `detect` rely on); the
        first field out of type, range or finiteness raises a one-line `UserError`."""
        f = CardFields(doc, path)
        if not isinstance(doc, dict):
            raise UserError(f"model card {path}: expected a JSON object, got {type(doc).__name__}")
        method = card_method(doc.get("format"))
        if method is None:
            raise UserError(f"{path} is not an aisdati model card")
        if doc.get("kind") != KIND or any(k not in doc for k in ("rule", "region", "data")):
            raise UserError(f"{path} is not an AIS model card (train one with `aisdati train`)")
        cluster, seed = f.text("cluster"), f.integer("seed", 0, MAX_SEED)
        rule, region = _read_rule(f), _read_region(f)
        lane = _read_lane(f)
        networks = _read_networks(f, method, lane)
        return cls(
            method=method, cluster=cluster, seed=seed, rule=rule, region=region,
            lane_config=lane, networks=networks, data=_read_data(f),
            calibration=_read_calibration(f), calibrated_with=_read_calibrated_with(f),
            training=_read_training(f), preset=doc.get("preset"), created=doc.get("created"),
            score=_read_score(f),
            code_version=doc.get("code_version"), epsilon_m=doc.get("epsilon_m"),
            epsilon_interpretation=doc.get("epsilon_interpretation"), files=_read_files(f),
        )  # fmt: skip


def read_card(path: Path) -> ModelCard:
    """The checked card in the file `path` (`ModelCard.from_dict`); any problem is one line."""
    if not path.is_file():
        raise UserError(f"model file not found: {path}")
    return ModelCard.from_dict(read_json(path), path)


def _present(doc: dict[str, Any]) -> dict[str, Any]:
    """`doc` without the entries that are None (fields a card need not have)."""
    return {k: v for k, v in doc.items() if v is not None}


# ------------------------------------------------------------------------- reading each section
def _read_rule(f: CardFields) -> RuleCard:
    """The update rule's ranges; the COG centre is optional (older cards: 180)."""
    sog = f.number("rule.max_sog_kn", 0.0, 1000.0, low_open=True)
    dt = f.number("rule.max_dt_h", 0.0, 24.0 * 366, low_open=True)
    center = None
    if f.get("rule.cog_center_deg", None) is not None:
        center = f.number("rule.cog_center_deg", -360.0, 360.0)
    return RuleCard(sog, dt, center)


def _read_region(f: CardFields) -> Region:
    return Region(f.interval("region.lon", -360.0, 360.0), f.interval("region.lat", -91.0, 91.0))


def _read_lane(f: CardFields) -> LaneConfig:
    """The lane configuration; cards from before lane configurations: the paper's."""
    lane = f.obj("lane_config", None)
    if lane is None:
        return LaneConfig()
    if "corridor_km" in lane:
        f.number("lane_config.corridor_km", 0.0, 1000.0, low_open=True)
    validation = {"validation_tracks": MAX_TRACKS, "validation_rollouts": MAX_VALIDATION_ROLLOUTS}
    for key, most in validation.items():
        if key in lane:
            f.integer(f"lane_config.{key}", 1, most)
    for key, least, most in (
        ("fourier", 0, MAX_FOURIER), ("pretrain", 0, MAX_PRETRAIN), ("members", 1, MAX_MEMBERS),
    ):  # fmt: skip
        if key in lane:
            f.integer(f"lane_config.{key}", least, most)
    try:
        return LaneConfig.from_dict(lane)
    except UserError as exc:  # a setting out of its choices
        raise UserError(f"model card {f.path}: lane_config: {exc}") from None
    except TypeError:
        known = ", ".join(LaneConfig().to_dict())
        raise f.fail("lane_config", f"an object of {known}", lane) from None


def _read_networks(f: CardFields, method: str, lane: LaneConfig) -> NetworkCard | None:
    """A learnt detector's seeds (one per member of its lane) and hyperparameters."""
    if method not in ("dati", "bc"):
        return None
    seeds = f.array("seeds", length=lane.members)
    for i, seed in enumerate(seeds):
        f.integer(f"seeds[{i}]", 0, MAX_SEED, value=seed)
    if method == "bc":
        config = f.obj("config")
        for key, value in config.items():
            if is_number(value):
                f.number(f"config.{key}", value=value)
        _read_sizes(f, "config", ("state_features", "time_embedding_dim", "hidden_units"))
        return NetworkCard(seeds=seeds, config=config)
    state_dim = f.choice("state_dim", (state_width(lane.state, lane.fourier),))
    decision_dim = f.integer("decision_dim", 3, 3)
    f.choice("config.noise", ("gaussian", "ou"))
    f.number("config.noise_sigma", 0.0, 100.0)
    f.number("config.ou_theta", 0.0, 100.0)
    f.number("config.ou_dt", 0.0, 100.0, low_open=True)
    f.integer("config.network.latent_dim", 1, MAX_UNITS)
    units = ("feature_units", "time_embedding_dim", "hidden_units")
    _read_sizes(f, "config.network", units)
    f.number("epsilon_m", 0.0, low_open=True)
    return NetworkCard(
        seeds=seeds, config=f.get("config"), state_dim=state_dim, decision_dim=decision_dim
    )


def _read_sizes(f: CardFields, section: str, units: Sequence[str]) -> None:
    """The network sizes a section sets (the others are the defaults): networks are built at
    them before the weights are read."""
    for key in (*units, "hidden_layers"):
        if f.get(f"{section}.{key}", None) is not None:
            f.integer(f"{section}.{key}", 1, MAX_LAYERS if key == "hidden_layers" else MAX_UNITS)


def _read_data(f: CardFields) -> DataCard:
    """The training tracks: ids, starts and (since 0.1.0) stable keys."""
    ids = f.array("data.track_ids", min_length=1, max_length=MAX_TRACKS)
    for i, v in enumerate(ids):
        f.integer(f"data.track_ids[{i}]", 0, MAX_COUNT, value=v)
    most = min(MAX_POINTS, len(ids) * MAX_TRACK_POINTS)
    points = f.integer("data.points", len(ids), most)  # the traffic rollouts run their mean
    for key, most in (("tracks_in_cluster", MAX_COUNT), ("tracks_used", MAX_TRACKS)):
        if f.get(f"data.{key}", None) is not None:
            f.integer(f"data.{key}", 0, most)
    starts = _read_points(f, "data.start_points", len(ids))
    ends = _read_points(f, "data.end_points", len(ids)) if f.get("data.end_points", None) else None
    ashore = f.get("data.ashore_points", None)
    if ashore is not None:
        ashore = _read_points(f, "data.ashore_points", max_length=points)
    keys = f.get("data.track_keys", None)
    if keys is not None:
        f.array("data.track_keys", length=len(ids))
        parse_track_keys(keys, f)
    data = f.get("data")
    source = {k: data.get(k) for k in ("dir", "files", "cluster", "tracks_in_cluster",
                                       "tracks_used", "time_span")}  # fmt: skip
    return DataCard(
        track_ids=ids, points=points, start_points=starts, end_points=ends, track_keys=keys,
        ashore_points=ashore, **source,
    )  # fmt: skip


def _read_points(
    f: CardFields, key: str, n: int | None = None, max_length: int | None = None
) -> list[list[float]]:
    """n (or at most `max_length`) [lon, lat] pairs in degrees."""
    points = f.array(key, length=n, max_length=max_length)
    for i, point in enumerate(points):
        name = f"{key}[{i}]"
        if not isinstance(point, list) or len(point) != 2:
            raise f.fail(name, "a [lon, lat] pair", point)
        f.number(f"{name}[0]", -180.0, 180.0, value=point[0])
        f.number(f"{name}[1]", -90.0, 90.0, value=point[1])
    return points


MODEL_FILES = (".pt", ".corridor.npz", ".npz")
"""The files a model may have beside its card, whose digests the card records."""


def _read_files(f: CardFields) -> dict[str, str] | None:
    """The digests of the model's files (absent in cards before them)."""
    files = f.obj("files", None)
    if files is None:
        return None
    for suffix, digest in files.items():
        if suffix not in MODEL_FILES or not isinstance(digest, str) or len(digest) != 64:
            raise f.fail(f"files.{suffix}", "a SHA-256 of one of the model's files", digest)
    return dict(files)


def file_digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write_model(
    stem: Path, files: dict[str, bytes], card: ModelCard, extra: dict[str, Any] | None = None
) -> None:
    """Write a model's files (by suffix), then its card, last, recording their digests
    (`ModelCard.files`; `extra`: entries of the card file beside the card's own): a model is
    its card, and a card never names files that are not its own (`check_files`)."""
    for suffix, data in files.items():
        atomic_write_bytes(stem.with_suffix(suffix), data)
    card.files = {suffix: file_digest(data) for suffix, data in files.items()}
    doc = {**(extra or {}), **card.to_dict()}
    atomic_write_bytes(stem.with_suffix(".json"), json.dumps(doc, indent=2, default=str).encode())


def check_files(stem: Path, card: ModelCard) -> None:
    """Refuse, in one line, a model whose files are not the ones its card was written with."""
    for suffix, digest in (card.files or {}).items():
        path = stem.with_suffix(suffix)
        found = file_digest(path.read_bytes()) if path.is_file() else None
        if found != digest:
            state = "is missing" if found is None else "is not the one its card records"
            raise UserError(
                f"model {stem}: {stem.name}{suffix} {state} (an interrupted or failed "
                "retraining into this folder?): retrain it"
            )


def _read_score(f: CardFields) -> str:
    """The score the model judges by; cards from before this field: lane. A score removed
    after `LAST_RELEASE_WITH_EXPERIMENTS` is refused in one line that names that release."""
    if f.get("score", None) is None:
        return "lane"
    if f.get("score") in REMOVED_SCORES:
        raise UserError(
            f"model card {f.path}: score {f.get('score')!r} was removed after aisdati "
            f"{LAST_RELEASE_WITH_EXPERIMENTS} (measured, not adopted): use that release to read "
            "this model, or retrain"
        )
    return f.choice("score", tuple(SCORES))


def _read_calibration(f: CardFields) -> dict[str, list[float]]:
    """The training tracks' own scores, which thresholds and `--score both` divide by."""
    calibration = f.obj("calibration", {})
    for key, values in calibration.items():
        f.array(f"calibration.{key}", min_length=1, max_length=MAX_TRACKS)
        for i, v in enumerate(values):
            f.number(f"calibration.{key}[{i}]", 0.0, value=v)
    return calibration


def _read_calibrated_with(f: CardFields) -> CalibratedWith | None:
    """The scoring settings of the calibration; older cards record fewer (or none)."""
    recorded = f.obj("calibrated_with", None)
    if recorded is None:
        return None
    settings = {}
    if "lane_course_km" in recorded:  # older cards: position only
        settings["lane_course_km"] = f.number("calibrated_with.lane_course_km", 0.0, 1000.0)
    if recorded.get("lane_traffic") is not None:  # older cards: without the traffic rollouts
        settings["lane_traffic"] = f.boolean("calibrated_with.lane_traffic")
    for key in ("rollouts", "lane_rollouts"):  # older cards: the command line's defaults
        if recorded.get(key) is not None:
            settings[key] = f.integer(f"calibrated_with.{key}", 1, MAX_DRAWS)
    if recorded.get("reported_motion") is not None:  # older cards: positions only
        settings["reported_motion"] = f.boolean("calibrated_with.reported_motion")
    return CalibratedWith(**settings)


def _read_training(f: CardFields) -> TrainingReport:
    """Training state: `detect` warns about a model whose training did not finish."""
    finished = f.boolean("training.finished")
    counts = {"episodes_run": (0, MAX_EPISODES), "episodes_max": (1, MAX_EPISODES),
              "routes_in_ensemble": (1, MAX_COUNT), "steps": (0, MAX_COUNT)}  # fmt: skip
    for key, (least, most) in counts.items():
        if f.get(f"training.{key}", None) is not None:
            f.integer(f"training.{key}", least, most)
    record = dict(f.obj("training", {}))
    typed = {k: record.pop(k, None) for k in TrainingReport.TYPED}
    typed["finished"] = finished
    return TrainingReport(**typed, details=record)


# ------------------------------------------------------------------------- the training tracks
def parse_track_keys(keys: Sequence[Any], fields: CardFields | None = None) -> pd.DataFrame:
    """`data.track_keys` ([mmsi, "start", "end"] per training track; "end" may be missing) as a
    frame of mmsi, start and end (UTC). The times are parsed together (ISO 8601): one by one,
    pandas took 0.4 ms a key, and every model load reads its card's keys."""
    f = fields or CardFields({}, "?")
    mmsi, texts = [], []
    for i, key in enumerate(keys):
        name = f"data.track_keys[{i}]"
        if not isinstance(key, list) or len(key) not in (2, 3):
            raise f.fail(name, '[mmsi, "start", "end"]', key)
        mmsi.append(f.integer(f"{name}[0]", 1, MAX_MMSI, value=key[0]))
        for j, text in enumerate(key[1:], start=1):
            if not isinstance(text, str):
                raise f.fail(f"{name}[{j}]", "an ISO 8601 time", text)
        texts += [key[1], key[-1]]
    stamps = pd.DatetimeIndex(
        pd.to_datetime(pd.Series(texts, dtype=object), utc=True, errors="coerce", format="ISO8601")
    )
    if stamps.isna().any():
        at = int(np.flatnonzero(stamps.isna())[0])
        key = keys[at // 2]
        j = 1 if at % 2 == 0 else len(key) - 1
        raise f.fail(f"data.track_keys[{at // 2}][{j}]", "an ISO 8601 time", key[j])
    start, end = stamps[0::2], stamps[1::2]
    if (end < start).any():
        i = int(np.flatnonzero(end < start)[0])
        raise f.fail(f"data.track_keys[{i}]", "a start before its end", keys[i])
    return pd.DataFrame({"mmsi": np.asarray(mmsi, np.int64), "start": start, "end": end})


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


def training_mask(card: ModelCard, tracks: pd.DataFrame) -> np.ndarray:
    """Which rows of a tracks.parquet frame (track_id, mmsi, start, end) are the model's training
    tracks. With `data.track_keys`: the same vessel over an overlapping time span (so re-ingesting
    with other settings, which renumbers tracks and may move a track's ends by a few reports,
    still finds them). Older cards without keys: by track id, as they were written."""
    if card.data.track_keys is None:
        ids = {int(i) for i in card.data.track_ids}
        return np.isin(tracks["track_id"].to_numpy(), list(ids))
    trained = parse_track_keys(card.data.track_keys)
    mask = np.zeros(len(tracks), dtype=bool)
    if trained.empty or tracks.empty:
        return mask
    start, end = _utc_ns(tracks["start"]), _utc_ns(tracks["end"])
    t0, t1 = _utc_ns(trained["start"]), _utc_ns(trained["end"])
    mmsi = tracks["mmsi"].to_numpy(np.int64)
    by_vessel = np.argsort(mmsi, kind="stable")
    vessels = mmsi[by_vessel]
    for m, keys in trained.groupby("mmsi").indices.items():
        rows = by_vessel[np.searchsorted(vessels, m) : np.searchsorted(vessels, m, "right")]
        if not rows.size:
            continue
        overlap = (start[rows, None] <= t1[None, keys]) & (end[rows, None] >= t0[None, keys])
        mask[rows[overlap.any(axis=1)]] = True
    return mask


def _utc_ns(times: pd.Series) -> np.ndarray:
    """Times as UTC datetime64[ns]: numpy compares those in bulk, where tz-aware values come
    out of pandas as an object array of Timestamps (a Python object per value, seconds at
    a quarter of a million tracks)."""
    return pd.DatetimeIndex(pd.to_datetime(times, utc=True)).tz_convert(None).to_numpy("M8[ns]")


# ------------------------------------------------------------------------------------ warnings
def card_warnings(card: ModelCard, name: str) -> list[str]:
    """What an operator should know before trusting a valid card's model."""
    tr = card.training
    if tr.finished is not False:
        return []
    return [
        f"model {name}: training did not finish (stopped after {tr.episodes_run} of "
        f"{tr.episodes_max} episodes), so its scores come from a partly trained model; "
        "finish it with `aisdati train --resume`"
    ]


def readable_cards(models_dir: Path, names: Sequence[str]) -> list[tuple[str, ModelCard]]:
    """The cards of the named models, or of every model in the folder, with their model names,
    read alone so that what they say comes before any work. Cards that cannot be read are left
    out here: loading them gives the error."""
    if names:
        stems = [models_dir / n for n in names]
    else:
        stems = sorted(p.with_suffix("") for p in models_dir.glob("*.json"))
    cards = []
    for stem in stems:
        try:
            cards.append((stem.name, read_card(stem.with_suffix(".json"))))
        except UserError:
            continue
    return cards


def card_methods(models_dir: Path, names: Sequence[str] = ()) -> set[str]:
    """The detectors of the named models, or of every model in the folder (`detect`'s default
    --method)."""
    return {card.method for _, card in readable_cards(models_dir, names)}


def unfinished_models(
    models_dir: Path, names: Sequence[str], method: str | None = None
) -> list[str]:
    """`card_warnings` of the models `detect` is about to load (the named ones, or every model of
    `method` in the folder), shown before any work."""
    return [
        warning
        for name, card in readable_cards(models_dir, names)
        if names or not method or card.method == method
        for warning in card_warnings(card, name)
    ]
