"""DATI on real AIS tracks (section 6 of the paper): the reference source, training and the card.

The environment is the foundation's `TrajectoryImitationEnv` with
- states (lon, lat) in degrees, decisions (SOG knots, COG degrees from north, dt hours) and the
  spherical update rule of eq. (5) (`SphericalRule`); the agent also learns the distribution of dt;
- references: the cluster's tracks, one per episode, cycling through a shuffled list so that
  N episodes over N tracks see every track once (the paper: 170 episodes, 170 tracks);
- the region: the training tracks' lon/lat box widened by `BOX_MARGIN` of its span on each side;
  a step that would leave it keeps the agent in place ("sticking");
- the reward's DTW is great-circle, and ε = 500 m is compared with the *mean* great-circle distance
  along the optimal warping path (DTW sum / path length, in metres). The paper does not say how
  500 m compares with a DTW sum, which grows with the track's length; the mean along the path is
  the reading of DESIGN.md and is written into every model card.
- scaling: states by the region's box; decisions by [0, max SOG] x [0, 360) x [0, max dt], the
  maxima being `DECISION_HEADROOM` x the largest perfect SOG and dt in the training tracks, so the
  perfect decisions of every training track are inside the box (a perfect policy reproduces them).
"""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import torch

from aisdati import __version__
from aisdati.errors import UserError
from aisdati.model.checkpoint import atomic_write_bytes, save_networks
from aisdati.model.dati import DATIConfig, DATITrainer, EpisodeLog
from aisdati.model.env import Reference, ReferenceSource, TrajectoryImitationEnv
from aisdati.model.resume import (
    at_episode_boundary,
    load_trainer_state,
    read_checkpoint,
    save_checkpoint,
)
from aisdati.model.rules import SphericalRule, mean_course
from aisdati.trackdata import Track, load_tracks, read_track_table, select_cluster

EPSILON_M = 500.0
"""The paper's ε for AIS, in metres (mean great-circle distance along the warping path)."""
EPSILON_READING = (
    "epsilon (metres) is compared with the exponentially smoothed mean great-circle distance "
    "along the optimal DTW warping path (DTW sum / number of path cells), not with the DTW sum"
)
BOX_MARGIN = 0.1
"""The region is the training tracks' box widened by this fraction of its span on each side."""
MIN_MARGIN_DEG = 0.01
DECISION_HEADROOM = 1.1


def track_reference(track: Track) -> Reference:
    return Reference(
        track.positions,
        track.dts,
        {"track_id": track.track_id, "mmsi": track.mmsi},
    )


def region_box(positions: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    allpos = np.concatenate(positions)
    lo, hi = allpos.min(axis=0), allpos.max(axis=0)
    margin = np.maximum((hi - lo) * BOX_MARGIN, MIN_MARGIN_DEG)
    return lo - margin, hi + margin


def fit_rule(tracks: Sequence[Track]) -> SphericalRule:
    """The spherical rule with decision ranges covering every training track's perfect decisions,
    its COG window centred on the tracks' distance-weighted mean course."""
    base = SphericalRule(max_sog=1.0, max_dt_h=1.0)
    decisions = np.concatenate([base.perfect_decisions(t.positions, t.dts) for t in tracks])
    max_sog = float(decisions[:, 0].max()) * DECISION_HEADROOM
    max_dt = float(decisions[:, 2].max()) * DECISION_HEADROOM
    center = mean_course(decisions[:, 1], weights=decisions[:, 0] * decisions[:, 2])
    return SphericalRule(max_sog=max(max_sog, 1.0), max_dt_h=max(max_dt, 1e-3), cog_center=center)


class AISTrackSource(ReferenceSource):
    """References from real tracks, one per episode, each track once per pass in shuffled order."""

    def __init__(
        self,
        references: Sequence[Reference],
        rule: SphericalRule,
        bounds: tuple[np.ndarray, np.ndarray],
    ) -> None:
        if not references:
            raise ValueError("no references")
        self.references = list(references)
        self.rule = rule
        self.bounds = (np.asarray(bounds[0], np.float64), np.asarray(bounds[1], np.float64))
        self.max_steps = max(r.steps for r in self.references)
        self.order: list[int] = []
        self.position = 0

    def sample(self, rng: np.random.Generator) -> Reference:
        if self.position >= len(self.order):
            self.order = [int(i) for i in rng.permutation(len(self.references))]
            self.position = 0
        ref = self.references[self.order[self.position]]
        self.position += 1
        return ref

    def normalize(self, distance: float, path_length: int) -> float:
        """Mean great-circle distance along the warping path, metres."""
        return distance / max(path_length, 1)

    def state_dict(self) -> dict[str, Any]:
        return {"order": list(self.order), "position": self.position}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.order = [int(i) for i in state["order"]]
        self.position = int(state["position"])


def make_env(source: AISTrackSource, epsilon: float = EPSILON_M) -> TrajectoryImitationEnv:
    return TrajectoryImitationEnv(source, epsilon=epsilon)


@dataclass(frozen=True)
class TrainSettings:
    data_dir: Path
    cluster: str
    out_dir: Path
    episodes: int = 170
    seed: int = 0
    max_tracks: int | None = 170
    """Downsample the cluster to this many tracks (the paper: 170); None keeps all."""
    patience: int = 10
    epsilon_m: float = EPSILON_M
    track_ids: tuple[int, ...] | None = None
    """Train on exactly these tracks of the cluster (`aisdati evaluate`'s split); None: all,
    downsampled to `max_tracks`."""
    stem: str | None = None
    """Model file name in `out_dir` (default: the cluster's name)."""
    resume: bool = False
    """Continue from <out>/<cluster>.ckpt (written after every episode) when it exists."""


@dataclass
class TrainResult:
    model: Path
    card: dict[str, Any]
    history: list[EpisodeLog]
    wall_seconds: float
    steps: int
    resumed_from: int = 0
    """Episodes already done by the checkpoint this run resumed from (0: a fresh run)."""


def code_version() -> str:
    try:
        rev = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
            timeout=5,
            cwd=Path(__file__).parent,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        rev = ""
    return f"aisdati {__version__}" + (f" ({rev})" if rev else "")


def choose_training_tracks(settings: TrainSettings) -> tuple[list[int], int]:
    """Track ids of the cluster, downsampled uniformly (seeded) to `max_tracks`; and the total."""
    table = select_cluster(read_track_table(settings.data_dir), settings.cluster, settings.data_dir)
    ids = np.sort(table["track_id"].to_numpy())
    total = len(ids)
    if settings.track_ids is not None:
        return sorted(int(i) for i in settings.track_ids), total
    if settings.max_tracks is not None and total > settings.max_tracks:
        rng = np.random.default_rng(settings.seed)
        ids = np.sort(rng.choice(ids, size=settings.max_tracks, replace=False))
    return [int(i) for i in ids], total


def build_source(tracks: Sequence[Track]) -> AISTrackSource:
    refs = [track_reference(t) for t in tracks]
    return AISTrackSource(refs, fit_rule(tracks), region_box([t.positions for t in tracks]))


def data_card(settings: TrainSettings, tracks: Sequence[Track], total: int) -> dict[str, Any]:
    table = read_track_table(settings.data_dir).set_index("track_id")
    used = table.loc[[t.track_id for t in tracks]]
    return {
        "dir": str(settings.data_dir),
        "files": [
            str(settings.data_dir / "points.parquet"),
            str(settings.data_dir / "tracks.parquet"),
        ],
        "cluster": settings.cluster,
        "tracks_in_cluster": total,
        "tracks_used": len(tracks),
        "track_ids": [t.track_id for t in tracks],
        "points": int(sum(len(t.positions) for t in tracks)),
        "time_span": [str(used["start"].min()), str(used["end"].max())],
        "start_points": [[float(t.positions[0, 0]), float(t.positions[0, 1])] for t in tracks],
    }


def base_card(
    settings: TrainSettings, source: AISTrackSource, data: dict[str, Any]
) -> dict[str, Any]:
    """What every AIS detector's card says: the data, the region and the decision ranges."""
    lo, hi = source.bounds
    return {
        "kind": "ais",
        "cluster": settings.cluster,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "code_version": code_version(),
        "seed": settings.seed,
        "data": data,
        "region": {"lon": [float(lo[0]), float(hi[0])], "lat": [float(lo[1]), float(hi[1])]},
        "rule": {
            "name": "spherical (eq. 5)",
            "decisions": ["sog_kn", "cog_deg", "dt_h"],
            "max_sog_kn": source.rule.max_sog,
            "max_dt_h": source.rule.max_dt_h,
            "cog_center_deg": source.rule.cog_center,
        },
    }


def model_card(
    settings: TrainSettings,
    source: AISTrackSource,
    data: dict[str, Any],
    history: Sequence[EpisodeLog],
    wall: float,
    steps: int,
) -> dict[str, Any]:
    logs = list(history)
    best = min(logs, key=lambda g: g.mean_loss) if logs else None
    return {
        **base_card(settings, source, data),
        "epsilon_m": settings.epsilon_m,
        "epsilon_interpretation": EPSILON_READING,
        "training": {
            "episodes_run": len(logs),
            "episodes_max": settings.episodes,
            "patience": settings.patience,
            "best_episode": best.episode if best else None,
            "stopped_early": bool(logs and logs[-1].stopped and len(logs) < settings.episodes),
            "mean_reward": [round(g.mean_reward, 4) for g in logs],
            "final_dtw_m": [round(g.final_dtw, 1) for g in logs],
            "mean_loss": [round(g.mean_loss, 5) for g in logs],
            "steps": steps,
            "wall_seconds": round(wall, 2),
            "steps_per_second": round(steps / wall, 2) if wall > 0 else None,
        },
    }


def model_stem(settings: TrainSettings) -> Path:
    return settings.out_dir / (settings.stem or settings.cluster)


StepCallback = Callable[[DATITrainer, list[EpisodeLog]], None]


def train_ais(settings: TrainSettings, on_step: StepCallback | None = None) -> TrainResult:
    """Train one DATI model on a cluster's tracks; writes <out>/<cluster>.pt, .json (the card) and
    .log.jsonl (one line per episode), the .pt and .json after every episode (best actor so far),
    so an interrupted run leaves a usable model."""
    if settings.episodes < 1:
        raise UserError(f"--episodes must be at least 1, got {settings.episodes}")
    if settings.max_tracks is not None and settings.max_tracks < 1:
        raise UserError(f"--max-tracks must be at least 1, got {settings.max_tracks}")
    torch.set_num_threads(1)  # one member of small networks: one thread is fastest (3x on 2 cores)
    ids, total = choose_training_tracks(settings)
    tracks = load_tracks(settings.data_dir, ids)
    source = build_source(tracks)
    data = data_card(settings, tracks, total)
    config = DATIConfig(episodes=settings.episodes, patience=settings.patience)
    env = make_env(source, settings.epsilon_m)
    trainer = DATITrainer([env], [settings.seed], config)
    stem = model_stem(settings)
    log_path = stem.with_suffix(".log.jsonl")
    ckpt_path = stem.with_suffix(".ckpt")
    log_lines: list[str] = []
    steps, wall_before, resumed_from = 0, 0.0, 0
    identity = {"cluster": settings.cluster, "seed": settings.seed, "track_ids": ids}
    if settings.resume and ckpt_path.is_file():
        doc = read_checkpoint(ckpt_path)
        if doc.get("identity") != identity:
            raise UserError(
                f"{ckpt_path} belongs to another run (cluster, seed or training tracks differ); "
                "use the same --seed/--max-tracks/--data, or train without --resume"
            )
        source.load_state_dict(doc["source"])
        by_id = {r.label["track_id"]: r for r in source.references}
        load_trainer_state(trainer, doc["trainer"], [by_id[int(i)] for i in doc["current"]])
        log_lines = list(doc["log_lines"])
        steps, wall_before = int(doc["steps"]), float(doc["wall_seconds"])
        resumed_from = len(trainer.history)
    elif settings.resume and stem.with_suffix(".json").is_file():
        try:
            old = json.loads(stem.with_suffix(".json").read_text())
        except (OSError, ValueError):
            old = {}
        same = old.get("seed") == settings.seed and old.get("data", {}).get("track_ids") == ids
        if same and old.get("training", {}).get("finished"):
            raise UserError(
                f"{stem.with_suffix('.pt')} has finished training: nothing to resume "
                "(drop --resume to train again)"
            )
    t0 = time.perf_counter()

    def elapsed() -> float:
        return wall_before + time.perf_counter() - t0

    def checkpoint() -> None:
        card = model_card(settings, source, data, trainer.history, elapsed(), steps)
        card["training"]["finished"] = trainer.done
        save_networks(stem, trainer.final, config, card)
        atomic_write_bytes(log_path, "".join(log_lines).encode())
        if trainer.done:
            ckpt_path.unlink(missing_ok=True)
        elif at_episode_boundary(trainer):
            extra = {
                "identity": identity,
                "source": source.state_dict(),
                "current": [int(e.reference.label["track_id"]) for e in trainer.envs],
                "log_lines": log_lines,
                "steps": steps,
                "wall_seconds": elapsed(),
            }
            save_checkpoint(ckpt_path, trainer, extra)

    while not trainer.done:
        logs = trainer.step()
        steps += 1
        for log in logs:
            row = {**log.__dict__, "wall_seconds": round(elapsed(), 3)}
            log_lines.append(json.dumps(row) + "\n")
        if logs:
            checkpoint()
        if on_step is not None:
            on_step(trainer, logs)
    if resumed_from and not steps:
        checkpoint()
    wall = elapsed()
    card = model_card(settings, source, data, trainer.history, wall, steps)
    card["training"]["finished"] = True
    return TrainResult(
        stem.with_suffix(".pt"), card, list(trainer.history), wall, steps, resumed_from
    )
