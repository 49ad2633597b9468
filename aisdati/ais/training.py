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
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import torch

from aisdati import __version__
from aisdati.ais.card import track_keys
from aisdati.ais.policy import AISPolicy, dati_act
from aisdati.ais.space import PRESETS, AISSpace, LaneConfig
from aisdati.errors import UserError
from aisdati.model.checkpoint import atomic_write_bytes, save_networks
from aisdati.model.dati import DATIConfig, DATITrainer, EpisodeLog
from aisdati.model.env import Reference, ReferenceSource, TrajectoryImitationEnv
from aisdati.model.networks import DATINetworks
from aisdati.model.resume import (
    load_trainer_state,
    read_checkpoint,
    save_checkpoint,
)
from aisdati.tracks.store import Track, load_tracks, read_track_table, select_cluster

EPSILON_M = 500.0
"""The paper's ε for AIS, in metres (mean great-circle distance along the warping path)."""
EPSILON_READING = (
    "epsilon (metres) is compared with the exponentially smoothed mean great-circle distance "
    "along the optimal DTW warping path (DTW sum / number of path cells), not with the DTW sum"
)


def track_reference(track: Track) -> Reference:
    return Reference(
        track.positions,
        track.dts,
        {"track_id": track.track_id, "mmsi": track.mmsi},
    )


class AISTrackSource(ReferenceSource):
    """References from real tracks, one per episode, each track once per pass in shuffled order."""

    def __init__(self, references: Sequence[Reference], space: AISSpace) -> None:
        if not references:
            raise ValueError("no references")
        self.references = list(references)
        self.space = space
        self.rule = space.rule
        self.bounds = space.bounds
        self.max_steps = max(r.steps for r in self.references)
        self.order: list[int] = []
        self.position = 0

    # the agent's view and moves are the space's (the same functions score tracks later)
    @property
    def state_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.space.state_bounds

    @property
    def time_high(self) -> float:
        return self.space.time_high(self.max_steps)

    def contains(self, position: np.ndarray) -> bool:
        return bool(self.space.contains(position))

    def resolve(self, position: np.ndarray, proposed: np.ndarray) -> np.ndarray:
        return self.space.resolve(position, proposed)

    def features(self, positions: np.ndarray, previous: np.ndarray, dts: np.ndarray) -> np.ndarray:
        return self.space.features(positions, previous, dts)

    def time_input(self, t: np.ndarray, horizon: int) -> np.ndarray:
        return self.space.time_input(t, horizon)

    def sample(self, rng: np.random.Generator) -> Reference:
        if self.position >= len(self.order):
            self.order = [int(i) for i in rng.permutation(len(self.references))]
            self.position = 0
        ref = self.references[self.order[self.position]]
        self.position += 1
        return ref

    def restart(self) -> None:
        self.order, self.position = [], 0

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
    preset: str = "lanes"
    """Name of the lane configuration (`aisdati.ais.space.PRESETS`) and its overrides."""
    lane: LaneConfig = field(default_factory=lambda: PRESETS["lanes"])
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


def build_source(tracks: Sequence[Track], config: LaneConfig | None = None) -> AISTrackSource:
    space = AISSpace.fit(
        [t.positions for t in tracks], [t.dts for t in tracks], config or LaneConfig()
    )
    return AISTrackSource([track_reference(t) for t in tracks], space)


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
        "track_keys": track_keys(used),
        "points": int(sum(len(t.positions) for t in tracks)),
        "time_span": [str(used["start"].min()), str(used["end"].max())],
        "start_points": [[float(t.positions[0, 0]), float(t.positions[0, 1])] for t in tracks],
    }


def base_card(
    settings: TrainSettings, source: AISTrackSource, data: dict[str, Any]
) -> dict[str, Any]:
    """What every AIS detector's card says: the data, the region, the decision ranges and the
    lane configuration (with the preset it came from)."""
    return {
        "kind": "ais",
        "cluster": settings.cluster,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "code_version": code_version(),
        "seed": settings.seed,
        "data": data,
        "preset": settings.preset,
        **source.space.card(),
    }


def model_card(
    settings: TrainSettings,
    source: AISTrackSource,
    data: dict[str, Any],
    history: Sequence[EpisodeLog],
    wall: float,
    steps: int,
    pretrained: dict[int, float | None],
) -> dict[str, Any]:
    """The card of a trained lane model; with several members (`LaneConfig.members`) the
    top-level curves are the first member's and `training.members` holds each member's.
    `pretrained` maps each member (as `EpisodeLog.member` numbers it) to its validation score
    after pretraining."""
    by_member: dict[int, list[EpisodeLog]] = {}
    for g in history:
        by_member.setdefault(g.member, []).append(g)
    validation, cap = source.space.config.validation, settings.episodes
    curves = [
        _curves(logs, validation, cap, pretrained.get(member))
        for member, logs in sorted(by_member.items())
    ]
    first = curves[0] if curves else _curves([], validation, cap, None)
    training = {
        **first,
        "episodes_max": settings.episodes,
        "patience": settings.patience,
        "selected_by": "validation rollouts" if source.space.config.validation else "loss",
        "steps": steps,
        "wall_seconds": round(wall, 2),
        "steps_per_second": round(steps / wall, 2) if wall > 0 else None,
    }
    if len(curves) > 1:
        training["members"] = curves
    return {
        **base_card(settings, source, data),
        "epsilon_m": settings.epsilon_m,
        "epsilon_interpretation": EPSILON_READING,
        "training": training,
    }


def _curves(
    logs: Sequence[EpisodeLog], validation: bool, episodes: int, pretrained: float | None
) -> dict[str, Any]:
    """One member's training curves and the episode its kept actor comes from (0: the
    pretrained actor, which no episode beat on validation)."""
    key = (lambda g: g.validation) if validation else (lambda g: g.mean_loss)
    best = min(logs, key=key) if logs else None
    best_episode = best.episode if best else None
    if pretrained is not None and (best is None or pretrained <= key(best)):
        best_episode = 0
    return {
        "episodes_run": len(logs),
        "best_episode": best_episode,
        "pretrained_validation_dtw_m": None if pretrained is None else round(pretrained, 1),
        "stopped_early": bool(logs and logs[-1].stopped and len(logs) < episodes),
        "mean_reward": [round(g.mean_reward, 4) for g in logs],
        "final_dtw_m": [round(g.final_dtw, 1) for g in logs],
        "mean_loss": [round(g.mean_loss, 5) for g in logs],
        "validation_dtw_m": [
            None if g.validation is None else round(g.validation, 1) for g in logs
        ],
    }


def dati_config(settings: TrainSettings, tracks: Sequence[Track]) -> DATIConfig:
    """The paper's hyperparameters, with OU latent noise at the data's median report interval
    (hours) and a state-aware critic when the lane configuration asks for them."""
    config = DATIConfig(episodes=settings.episodes, patience=settings.patience)
    if settings.lane.noise == "ou":
        dt = float(np.median(np.concatenate([t.dts for t in tracks])))
        config = replace(config, noise="ou", ou_dt=dt)
    if settings.lane.critic == "state":
        config = config.with_network(conditional_critic=True)
    return replace(
        config, pretrain_epochs=settings.lane.pretrain, actor_average=settings.lane.average
    )


def demonstrations(envs: Sequence[TrajectoryImitationEnv]) -> list[tuple[np.ndarray, ...]]:
    """Each environment's training tracks as supervised pairs (states, time inputs, scaled
    perfect decisions), for `DATITrainer.pretrain`."""
    out = []
    for env in envs:
        parts = [env.demonstration(ref) for ref in env.source.references]
        out.append(tuple(np.concatenate(p) for p in zip(*parts, strict=True)))
    return out


class Validator:
    """Scores a live DATI actor by its rollouts (best of R, from each validation track's first
    point) against `validation_tracks` of the training tracks: the median mean great-circle DTW
    in metres. Lower is better; the trainer keeps the best actor and stops on it."""

    def __init__(
        self,
        space: AISSpace,
        config: DATIConfig,
        tracks: Sequence[Track],
        lane: LaneConfig,
        seed: int,
    ):
        rng = np.random.default_rng([seed, 7])
        pick = rng.permutation(len(tracks))[: lane.validation_tracks]
        self.tracks = [tracks[i].positions for i in sorted(pick)]
        self.space, self.config = space, config
        self.rollouts, self.seed = lane.validation_rollouts, seed

    def __call__(self, trainer: DATITrainer, k: int) -> float:
        policy = AISPolicy(self.space, dati_act(trainer.candidate, self.config, member=k))
        scores = policy.rollout_scores(self.tracks, self.rollouts, self.seed)[0]
        return float(np.median(scores))


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
    source = build_source(tracks, settings.lane)
    data = data_card(settings, tracks, total)
    config = dati_config(settings, tracks)
    members = settings.lane.members
    # each member draws its own episode order from the same tracks
    envs = [
        make_env(AISTrackSource(source.references, source.space), settings.epsilon_m)
        for _ in range(members)
    ]
    validate = None
    if settings.lane.validation:
        validator = Validator(source.space, config, tracks, settings.lane, settings.seed)
        validate = _MemberValidators([validator] * members)
    trainer = DATITrainer(envs, member_seeds(settings.seed, members), config, validate)
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
        by_id = {r.label["track_id"]: r for r in source.references}
        load_trainer_state(trainer, doc["trainer"], [by_id[int(i)] for i in doc["current"]])
        orders = doc["source"]  # each live member's episode order (one dict before ensembles)
        orders = orders if isinstance(orders, list) else [orders] * len(trainer.envs)
        for env, order in zip(trainer.envs, orders, strict=True):
            env.source.load_state_dict(order)
        log_lines = list(doc["log_lines"])
        steps, wall_before = int(doc["steps"]), float(doc["wall_seconds"])
        resumed_from = len(trainer.history)  # >= 1: checkpoints are written after episodes
    elif settings.resume and stem.with_suffix(".json").is_file():
        try:
            old = json.loads(stem.with_suffix(".json").read_text())
        except (OSError, ValueError):
            old = {}
        if not isinstance(old, dict) or not all(
            isinstance(old.get(k, {}), dict) for k in ("data", "training")
        ):
            old = {}  # a damaged card: nothing to compare with (detect refuses it, naming why)
        same = old.get("seed") == settings.seed and old.get("data", {}).get("track_ids") == ids
        if same and old.get("training", {}).get("finished"):
            raise UserError(
                f"{stem.with_suffix('.pt')} has finished training: nothing to resume "
                "(drop --resume to train again)"
            )
    t0 = time.perf_counter()
    if not resumed_from:
        trainer.pretrain(demonstrations(envs))
    pretrained = dict(enumerate(trainer.pretrained_metric))  # members 0 .. M-1

    def elapsed() -> float:
        return wall_before + time.perf_counter() - t0

    def checkpoint() -> None:
        card = model_card(settings, source, data, trainer.history, elapsed(), steps, pretrained)
        card["training"]["finished"] = trainer.done
        save_networks(stem, trainer.final, config, card)
        if source.space.corridor is not None:
            corridor_path = stem.with_suffix(".corridor.npz")
            if not corridor_path.is_file():
                atomic_write_bytes(corridor_path, source.space.corridor.to_bytes())
        atomic_write_bytes(log_path, "".join(log_lines).encode())
        if trainer.done:
            ckpt_path.unlink(missing_ok=True)
        else:
            extra = {
                "identity": identity,
                "source": [env.source.state_dict() for env in trainer.envs],
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
    card = model_card(settings, source, data, trainer.history, wall, steps, pretrained)
    card["training"]["finished"] = True
    return TrainResult(
        stem.with_suffix(".pt"), card, list(trainer.history), wall, steps, resumed_from
    )


class _MemberValidators:
    """One `Validator` per ensemble member (each route validates on its own tracks; the seeds
    of one lane share theirs)."""

    def __init__(self, validators: Sequence[Validator]):
        self.validators = list(validators)

    def __call__(self, trainer: DATITrainer, k: int) -> float:
        return self.validators[trainer.active[k]](trainer, k)


def member_seeds(seed: int, members: int) -> list[int]:
    """Seeds of a lane's members: the first is the run's own seed, so one member is a plain run."""
    return [seed + 1000 * m for m in range(members)]


def member_networks(nets: DATINetworks, ks: slice) -> DATINetworks:
    """Members `ks` of an ensemble as a network of their own (every parameter has the members
    first)."""
    part = DATINetworks(
        nets.forward_actor.input_features.weight.shape[1],
        nets.forward_actor.out.weight.shape[2],
        nets.cfg,
        nets.seeds[ks],
    )
    part.load_state_dict({n: p[ks].clone() for n, p in nets.state_dict().items()})
    return part


def train_ais_ensemble(
    settings: Sequence[TrainSettings],
    on_step: StepCallback | None = None,
) -> list[TrainResult]:
    """Train one DATI model per settings (one per route) as ONE batched ensemble: each route is a
    member with its own tracks, region, rule, validation and early stopping; every layer runs
    all members in one batched matmul, so ten routes cost far less than ten runs. Each member is
    saved as its own model (<out>/<route>.pt/.json). No checkpoints: --resume is per model."""
    if not settings:
        raise UserError("no route to train")
    torch.set_num_threads(1)
    if len({s.lane for s in settings}) > 1:
        raise UserError("routes trained as one ensemble need one configuration (same --lane)")
    members = settings[0].lane.members  # per route: route i holds members i*M .. i*M + M-1
    sources, datas, groups, envs = [], [], [], []
    for s in settings:
        ids, total = choose_training_tracks(s)
        tracks = load_tracks(s.data_dir, ids)
        groups.append(tracks)
        sources.append(build_source(tracks, s.lane))
        datas.append(data_card(s, tracks, total))
        envs += [
            make_env(AISTrackSource(sources[-1].references, sources[-1].space), s.epsilon_m)
            for _ in range(members)
        ]
    # one configuration for all members (OU noise at the median dt of all routes' tracks)
    config = dati_config(settings[0], [t for g in groups for t in g])
    validators = [
        Validator(src.space, config, g, s.lane, s.seed)
        for src, g, s in zip(sources, groups, settings, strict=True)
        for _ in range(members)
    ]
    validate = _MemberValidators(validators) if settings[0].lane.validation else None
    seeds = member_seeds(settings[0].seed, members * len(settings))
    t0 = time.perf_counter()
    trainer = DATITrainer(envs, seeds, config, validate)
    trainer.pretrain(demonstrations(envs))
    steps = 0
    while not trainer.done:
        logs = trainer.step()
        steps += 1
        if on_step is not None:
            on_step(trainer, logs)
    wall = time.perf_counter() - t0
    results = []
    for k, s in enumerate(settings):
        mine = slice(k * members, (k + 1) * members)
        history = [h for h in trainer.history if mine.start <= h.member < mine.stop]
        stem = model_stem(s)
        starts = {m: trainer.pretrained_metric[m] for m in range(mine.start, mine.stop)}
        card = model_card(s, sources[k], datas[k], history, wall, steps, starts)
        card["seed"] = seeds[mine.start]
        card["training"]["finished"] = True
        card["training"]["routes_in_ensemble"] = len(settings)
        save_networks(stem, member_networks(trainer.final, mine), config, card)
        if sources[k].space.corridor is not None:
            atomic_write_bytes(
                stem.with_suffix(".corridor.npz"), sources[k].space.corridor.to_bytes()
            )
        log = "".join(json.dumps(h.__dict__) + "\n" for h in history)
        atomic_write_bytes(stem.with_suffix(".log.jsonl"), log.encode())
        results.append(TrainResult(stem.with_suffix(".pt"), card, history, wall, steps))
    return results
