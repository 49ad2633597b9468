"""DATI on real AIS tracks (section 6 of the paper): training one model per route, and its card.

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

One path trains every DATI model (`train_lanes`): N routes x M seeds as one batched ensemble,
each route a group of members with its own tracks, region, rule, validation and early stopping,
so ten routes cost far less than ten runs. One route is an ensemble of one route
(`train_ais`, `aisdati train --cluster X`); every route of an area is `aisdati train --cluster
routes`. The reference source and environment are `aisdati.ais.source`.
"""

from __future__ import annotations

import functools
import json
import subprocess
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import torch

from aisdati import __version__
from aisdati.ais import DEFAULT_PRESET
from aisdati.ais.card import (
    DataCard,
    ModelCard,
    NetworkCard,
    Region,
    RuleCard,
    TrainingReport,
    write_model,
)
from aisdati.ais.corridor import Corridor
from aisdati.ais.policy import AISPolicy, dati_act
from aisdati.ais.source import EPSILON_M, AISTrackSource, build_source, make_env
from aisdati.ais.space import PRESETS, AISSpace, LaneConfig, preset_score
from aisdati.errors import UserError
from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.model.env import TrajectoryImitationEnv
from aisdati.model.networks import DATINetworks
from aisdati.model.persistence import (
    load_error,
    network_bytes,
    network_meta,
    read_checkpoint,
    save_checkpoint,
)
from aisdati.model.readers import read_json
from aisdati.model.trainer import Callback, EpisodeLog
from aisdati.outdir import atomic_write_bytes
from aisdati.tracks.store import Track, load_tracks, read_track_table, select_cluster

EPSILON_READING = (
    "epsilon (metres) is compared with the exponentially smoothed mean great-circle distance "
    "along the optimal DTW warping path (DTW sum / number of path cells), not with the DTW sum"
)


@dataclass(frozen=True)
class TrainSettings:
    """How to train a detector. `data_dir` and `cluster` select the tracks of an ingest folder
    (`aisdati train`); a detector fitted on tracks in memory needs neither, and writes no files
    without `out_dir`."""

    data_dir: Path | None = None
    cluster: str = "tracks"
    """The cluster or route of `data_dir` to train on (the name of the tracks in the card)."""
    out_dir: Path | None = None
    episodes: int = 170
    seed: int = 0
    max_tracks: int | None = 170
    """Downsample the cluster to this many tracks (the paper: 170); None keeps all."""
    patience: int = 10
    epsilon_m: float = EPSILON_M
    preset: str = DEFAULT_PRESET
    """Name of the lane configuration (`aisdati.ais.space.PRESETS`) and its overrides."""
    lane: LaneConfig = field(default_factory=lambda: PRESETS[DEFAULT_PRESET])
    track_ids: tuple[int, ...] | None = None
    """Train on exactly these tracks of the cluster (`aisdati evaluate`'s split); None: all,
    downsampled to `max_tracks`."""
    stem: str | None = None
    """Model file name in `out_dir` (default: the cluster's name)."""
    resume: bool = False
    """Continue from <out>/<stem>.ckpt (written after every episode) when it exists."""
    device: str = "cpu"
    """Where DATI's networks train and calibrate (`aisdati.execution.device`); not part of
    the model: a checkpoint resumes on any device."""
    publish_to: str | None = None
    """A URL (`aisdati.storage`) the model is copied to once written: the task that trains
    it writes into a local folder of its own instead of `out_dir`."""


def check_settings(settings: TrainSettings) -> None:
    if settings.episodes < 1:
        raise UserError(f"--episodes must be at least 1, got {settings.episodes}")
    if settings.max_tracks is not None and settings.max_tracks < 1:
        raise UserError(f"--max-tracks must be at least 1, got {settings.max_tracks}")


def model_stem(settings: TrainSettings) -> Path | None:
    """<out>/<stem> of the settings' model files; None without `out_dir` (nothing is written)."""
    if settings.out_dir is None:
        return None
    return settings.out_dir / (settings.stem or settings.cluster)


# ------------------------------------------------------------------------ the training tracks
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


def data_card(settings: TrainSettings, tracks: Sequence[Track], total: int) -> DataCard:
    """The card's data section of tracks read from the ingest folder: the files, the cluster and
    the tracks' stable keys from tracks.parquet."""
    table = read_track_table(settings.data_dir).set_index("track_id")
    files = [str(settings.data_dir / n) for n in ("points.parquet", "tracks.parquet")]
    spans = table.loc[[t.track_id for t in tracks]]
    return DataCard.of_tracks(
        tracks, spans, dir=str(settings.data_dir), files=files, cluster=settings.cluster,
        tracks_in_cluster=total,
    )  # fmt: skip


def training_set(settings: TrainSettings) -> tuple[list[Track], DataCard]:
    """The settings' training tracks of the ingest folder, and the card's data section."""
    check_settings(settings)
    if settings.data_dir is None:
        raise UserError("training from an ingest folder needs the folder (--data)")
    ids, total = choose_training_tracks(settings)
    tracks = load_tracks(settings.data_dir, ids)
    return tracks, data_card(settings, tracks, total)


# ------------------------------------------------------------------------------------- cards
@functools.cache
def code_version() -> str:
    """`aisdati <version> (<git describe>)`, looked up once per process (cards are written after
    every episode)."""
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


def base_card(method: str, settings: TrainSettings, space: AISSpace, data: DataCard) -> ModelCard:
    """What every AIS detector's card says: the data, the region, the decision ranges and the
    lane configuration (with the preset it came from)."""
    return ModelCard(
        method=method,
        cluster=settings.cluster,
        created=datetime.now(timezone.utc).isoformat(timespec="seconds"),
        code_version=code_version(),
        seed=settings.seed,
        data=data,
        preset=settings.preset,
        score=preset_score(settings.preset, method),
        region=Region.from_bounds(space.bounds),
        rule=RuleCard.from_rule(space.rule),
        lane_config=space.config,
    )


def model_card(
    settings: TrainSettings,
    space: AISSpace,
    data: DataCard,
    history: Sequence[EpisodeLog],
    wall: float,
    steps: int,
    pretrained: dict[int, float | None],
) -> ModelCard:
    """The card of a trained lane model; with several members (`LaneConfig.members`) the
    top-level curves are the first member's and `details["members"]` holds each member's.
    `pretrained` maps each member (as `EpisodeLog.member` numbers it) to its validation score
    after pretraining."""
    by_member: dict[int, list[EpisodeLog]] = {}
    for g in history:
        by_member.setdefault(g.member, []).append(g)
    validation, cap = space.config.validation, settings.episodes
    curves = [
        member_curves(logs, validation, cap, pretrained.get(member))
        for member, logs in sorted(by_member.items())
    ]
    first = dict(curves[0] if curves else member_curves([], validation, cap, None))
    details = {
        **first,
        "patience": settings.patience,
        "selected_by": (
            f"validation {'one-step errors' if space.config.validate_by == 'step' else 'rollouts'}"
            if validation
            else "loss"
        ),
        "steps": steps,
        "steps_per_second": round(steps / wall, 2) if wall > 0 else None,
    }
    if len(curves) > 1:
        details["members"] = curves
    card = base_card("dati", settings, space, data)
    card.epsilon_m, card.epsilon_interpretation = settings.epsilon_m, EPSILON_READING
    card.training = TrainingReport(
        episodes_run=details.pop("episodes_run"),
        episodes_max=settings.episodes,
        wall_seconds=round(wall, 2),
        details=details,
    )
    return card


def member_curves(
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


# ------------------------------------------------------------------------- what DATI trains with
def dati_config(settings: TrainSettings, tracks: Sequence[Track]) -> DATIConfig:
    """The paper's hyperparameters, with OU latent noise at the data's median report interval
    (hours) when the lane configuration asks for it."""
    config = DATIConfig(episodes=settings.episodes, patience=settings.patience)
    if settings.lane.noise == "ou":
        dt = float(np.median(np.concatenate([t.dts for t in tracks])))
        config = replace(config, noise="ou", ou_dt=dt)
    return replace(config, pretrain_epochs=settings.lane.pretrain)


def demonstrations(envs: Sequence[TrajectoryImitationEnv]) -> list[tuple[np.ndarray, ...]]:
    """Each environment's training tracks as supervised pairs (states, time inputs, scaled
    perfect decisions), for `DATITrainer.pretrain`."""
    out = []
    for env in envs:
        parts = [env.demonstration(ref) for ref in env.source.references]
        out.append(tuple(np.concatenate(p) for p in zip(*parts, strict=True)))
    return out


def crossfit_folds(tracks: Sequence[Track], folds: int, seed: int) -> np.ndarray:
    """Fold (0 .. folds - 1) of each track for cross-fitting (`LaneConfig.crossfit`): vessels
    in seeded order, each to the fold with the fewest tracks so far, so that no vessel's other
    tracks teach the member that is calibrated on it; with fewer vessels than folds, tracks in
    seeded order, dealt round."""
    rng = np.random.default_rng([seed, 11])
    mmsi = np.array([t.mmsi for t in tracks])
    out = np.empty(len(tracks), dtype=np.int64)
    vessels = np.unique(mmsi)
    if len(vessels) < folds:
        out[rng.permutation(len(tracks))] = np.arange(len(tracks)) % folds
        return out
    sizes = np.zeros(folds, dtype=np.int64)
    for v in rng.permutation(vessels):
        mine = mmsi == v
        fold = int(np.argmin(sizes))
        out[mine] = fold
        sizes[fold] += int(mine.sum())
    return out


class Validator:
    """Scores a live DATI actor by its rollouts (best of R, from each validation track's first
    point) against `validation_tracks` of the given tracks (the training tracks, or with
    cross-fitting the member's held-out fold): the median mean great-circle DTW in metres
    (`validate_by="step"`: the median of the tracks' mean one-step errors, best of R draws).
    Lower is better; the trainer keeps the best actor and stops on it."""

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
        self.dts = [tracks[i].dts for i in sorted(pick)]
        self.space, self.config, self.by = space, config, lane.validate_by
        self.rollouts, self.seed = lane.validation_rollouts, seed

    def __call__(self, trainer: DATITrainer, k: int) -> float:
        policy = AISPolicy(self.space, dati_act(trainer.nets, self.config, member=k))
        if self.by == "step":  # `validate_by`: the mean one-step error of each track
            errors = policy.step_errors(self.tracks, self.dts, self.rollouts, self.seed)[0]
            return float(np.median([e.mean() for e in errors]))
        scores = policy.rollout_scores(self.tracks, self.rollouts, self.seed)[0]
        return float(np.median(scores))


class MemberValidators:
    """One `Validator` per ensemble member (each route validates on its own tracks; the seeds
    of one lane share theirs, or with cross-fitting each validates on its held-out fold)."""

    def __init__(self, validators: Sequence[Validator]):
        self.validators = list(validators)

    def __call__(self, trainer: DATITrainer, k: int) -> float:
        return self.validators[trainer.active[k]](trainer, k)


def check_crossfit(lane: LaneConfig, tracks_of: dict[str, int]) -> None:
    """Cross-fitting M members needs two tracks a fold in every model (`tracks_of`: its
    tracks by name), so that each member fits some and is calibrated on others."""
    short = [name for name, count in tracks_of.items() if count < 2 * lane.members]
    if lane.crossfit and short:
        raise UserError(
            f"cross-fitting {lane.members} members needs at least {2 * lane.members} tracks "
            f"per model ({', '.join(short)} has fewer): pass --lane crossfit=false"
        )


def member_sources(source: AISTrackSource, folds: np.ndarray, members: int) -> list[AISTrackSource]:
    """Each member's training tracks: all but its own cross-fitting fold (`crossfit_folds`;
    all of them where the folds are -1), in the source's space."""
    return [
        AISTrackSource(
            [r for r, f in zip(source.references, folds, strict=True) if f != m], source.space
        )
        for m in range(members)
    ]


def member_seeds(seed: int, members: int) -> list[int]:
    """Seeds of a lane's members: the first is the run's own seed, so one member is a plain run."""
    return [seed + 1000 * m for m in range(members)]


def member_networks(nets: DATINetworks, ks: slice) -> DATINetworks:
    """Members `ks` of an ensemble as a network of their own (every parameter has the members
    first)."""
    part = DATINetworks(nets.state_dim, nets.decision_dim, nets.cfg, nets.seeds[ks])
    part.load_state_dict({n: p[ks].clone() for n, p in nets.state_dict().items()})
    return part


# --------------------------------------------------------------------------- training: one path
@dataclass
class LaneRoute:
    """One route's (or cluster's) training tracks and its card's data section: a group of the
    ensemble's members learns them (`LaneConfig.members` seeds)."""

    settings: TrainSettings
    tracks: list[Track]
    data: DataCard

    @property
    def stem(self) -> Path | None:
        return model_stem(self.settings)


@dataclass
class TrainResult:
    model: Path | None
    """<out>/<stem>.pt; None when trained without `out_dir` (nothing written)."""
    card: ModelCard
    networks: DATINetworks
    config: DATIConfig
    corridor: Corridor | None
    """The corridor the route's agents moved in (`region="corridor"`)."""
    history: list[EpisodeLog]
    wall_seconds: float
    steps: int
    resumed_from: int = 0
    """Episodes already done by the checkpoint this run resumed from (0: a fresh run)."""


class EnsembleRun:
    """N routes x M seeds trained as one batched `DATITrainer`: route k holds members
    k*M .. k*M + M-1, each member its own episode order over its route's tracks, and every
    layer runs all members in one batched matmul. After every episode a route's members end,
    its model files are written (<out>/<stem>.pt, .json, .log.jsonl: the best actors so far),
    so an interrupted run leaves usable models. A one-route run also keeps a checkpoint
    (<stem>.ckpt) that `--resume` continues from exactly: it holds the whole trainer."""

    def __init__(self, routes: Sequence[LaneRoute], first_member: int = 0):
        if not routes:
            raise UserError("no route to train")
        if len({r.settings.lane for r in routes}) > 1:
            raise UserError("routes trained as one ensemble need one configuration (same --lane)")
        if len(routes) > 1 and any(r.settings.resume for r in routes):
            raise UserError("--resume continues one model: resume each route on its own")
        for r in routes:
            check_settings(r.settings)
        self.routes = list(routes)
        first = self.routes[0].settings
        self.members = first.lane.members
        check_crossfit(first.lane, {r.settings.cluster: len(r.tracks) for r in self.routes})
        self.sources = [build_source(r.tracks, r.settings.lane) for r in self.routes]
        self.corridor_files = [
            None if s.space.corridor is None else s.space.corridor.to_bytes() for s in self.sources
        ]
        """Each route's corridor as its file holds it, serialised once for the run's saves."""
        # the members' seeds count from `first_member`: a route's seeds are the same whether it
        # trains alone or beside others (`aisdati.detectors.train.route_tasks`)
        self.seeds = member_seeds(first.seed, first_member + self.members * len(self.routes))
        self.seeds = self.seeds[first_member:]
        # each member's tracks: its route's, or with cross-fitting all but its own fold
        self.folds = [
            crossfit_folds(r.tracks, self.members, self.seeds[k * self.members])
            if first.lane.crossfit
            else np.full(len(r.tracks), -1)
            for k, r in enumerate(self.routes)
        ]
        envs = [  # each member draws its own episode order from its tracks
            make_env(member_source, r.settings.epsilon_m)
            for r, src, folds in zip(self.routes, self.sources, self.folds, strict=True)
            for member_source in member_sources(src, folds, self.members)
        ]
        # one configuration for all members (OU noise at the median dt of all routes' tracks)
        self.config = dati_config(first, [t for r in self.routes for t in r.tracks])
        validate = None
        if first.lane.validation:
            validate = MemberValidators(
                [
                    Validator(
                        src.space,
                        self.config,
                        [t for t, f in zip(r.tracks, folds, strict=True) if f in (-1, m)],
                        r.settings.lane,
                        r.settings.seed,
                    )
                    for r, src, folds in zip(self.routes, self.sources, self.folds, strict=True)
                    for m in range(self.members)
                ]
            )
        self.envs = envs
        self.trainer = DATITrainer(envs, self.seeds, self.config, validate, device=first.device)
        self.log_lines: list[list[str]] = [[] for _ in self.routes]
        self.steps, self.wall_before, self.resumed_from = 0, 0.0, 0
        self.started = time.perf_counter()
        stem = self.routes[0].stem
        alone = len(self.routes) == 1 and stem is not None
        self.checkpoint_path = stem.with_suffix(".ckpt") if alone else None

    # -------------------------------------------------------------------------- members
    def members_of(self, k: int) -> range:
        return range(k * self.members, (k + 1) * self.members)

    def route_of(self, member: int) -> int:
        return member // self.members

    def history(self, k: int) -> list[EpisodeLog]:
        return [h for h in self.trainer.history if h.member in self.members_of(k)]

    def route_done(self, k: int) -> bool:
        return not any(m in self.members_of(k) for m in self.trainer.active)

    def networks(self, k: int) -> DATINetworks:
        """Route k's members' kept actors (best or final) as a network of their own."""
        mine = self.members_of(k)
        return member_networks(self.trainer.model(), slice(mine.start, mine.stop))

    def elapsed(self) -> float:
        return self.wall_before + time.perf_counter() - self.started

    def card(self, k: int, nets: DATINetworks, wall: float) -> ModelCard:
        route, mine = self.routes[k], self.members_of(k)
        pretrained = {m: self.trainer.pretrained_metric[m] for m in mine}
        space = self.sources[k].space
        card = model_card(
            route.settings, space, route.data, self.history(k), wall, self.steps, pretrained
        )
        card.seed = self.seeds[mine.start]
        card.networks = NetworkCard(
            seeds=nets.seeds, config=self.config.to_dict(), state_dim=nets.state_dim,
            decision_dim=nets.decision_dim,
        )  # fmt: skip
        # a model is finished once calibrated: the detector's own save says so, after it; a
        # run stopped between its last episode and its calibration is not (issue 61, item 12)
        card.training.finished = False
        if len(self.routes) > 1:
            card.training.routes_in_ensemble = len(self.routes)
        return card

    # ----------------------------------------------------------------------------- files
    def identity(self) -> dict[str, Any]:
        """What a checkpoint must match to be resumed by this run: the tracks, the seed and the
        lane configuration (which sizes the networks)."""
        s = self.routes[0].settings
        return {"cluster": s.cluster, "seed": s.seed, "track_ids": self.routes[0].data.track_ids,
                "lane": s.lane.to_dict()}  # fmt: skip

    def resume(self) -> None:
        """Continue from the route's checkpoint (`TrainSettings.resume`); without one, refuse to
        resume a model whose training finished. A checkpoint of another run, or a damaged one,
        is a one-line `UserError`."""
        stem, path = self.routes[0].stem, self.checkpoint_path
        if not self.routes[0].settings.resume or stem is None:
            return
        if path is not None and path.is_file():
            doc = read_checkpoint(path, CHECKPOINT_ENTRIES)
            check_identity(path, doc["identity"], self.identity())
            try:
                self.load_checkpoint(doc)
            except UserError as exc:
                raise UserError(f"checkpoint {path} is damaged: {exc}") from None
            except (KeyError, IndexError, TypeError, ValueError, RuntimeError) as exc:
                raise UserError(
                    f"checkpoint {path} is damaged ({load_error(exc)}): delete it or drop --resume"
                ) from None
            self.resumed_from = len(self.trainer.history)  # >= 1: written after episodes
        elif stem.with_suffix(".json").is_file():
            self.refuse_finished(stem)

    def load_checkpoint(self, doc: dict[str, Any]) -> None:
        """Put the trainer, the episode orders, the log and the counters where `doc` (a
        checkpoint of this run, `save`) left them."""
        by_id = {r.label["track_id"]: r for r in self.sources[0].references}
        unknown = [i for i in doc["current"] if int(i) not in by_id]
        if unknown:
            raise UserError(f"its episodes run on tracks {unknown} this run does not train on")
        self.trainer.load_state_dict(doc["trainer"], [by_id[int(i)] for i in doc["current"]])
        orders = doc["source"]  # each live member's episode order (one dict before ensembles)
        orders = orders if isinstance(orders, list) else [orders] * len(self.trainer.envs)
        for env, order in zip(self.trainer.envs, orders, strict=True):
            env.source.load_state_dict(order)
        self.log_lines[0] = [str(line) for line in doc["log_lines"]]
        self.steps, self.wall_before = int(doc["steps"]), float(doc["wall_seconds"])

    def refuse_finished(self, stem: Path) -> None:
        """`--resume` of a model that finished training (and so left no checkpoint)."""
        try:
            old = read_json(stem.with_suffix(".json"))
        except UserError:
            old = {}
        if not isinstance(old, dict) or not all(
            isinstance(old.get(k, {}), dict) for k in ("data", "training")
        ):
            old = {}  # a damaged card: nothing to compare with (detect refuses it, naming why)
        ids = self.routes[0].data.track_ids
        same = old.get("seed") == self.routes[0].settings.seed
        same = same and old.get("data", {}).get("track_ids") == ids
        if same and old.get("training", {}).get("finished"):
            raise UserError(
                f"{stem.with_suffix('.pt')} has finished training: nothing to resume "
                "(drop --resume to train again)"
            )

    def save(self, routes: set[int]) -> None:
        """Write the models of `routes` as they stand, and the checkpoint of a one-route run."""
        wall = self.elapsed()
        for k in sorted(routes):
            stem = self.routes[k].stem
            if stem is None:
                continue
            nets = self.networks(k)
            files = {".pt": network_bytes(nets)}
            if self.corridor_files[k] is not None:  # this run's, whatever was there
                files[".corridor.npz"] = self.corridor_files[k]
            card = self.card(k, nets, wall)
            write_model(stem, files, card, network_meta(nets, self.config))
            atomic_write_bytes(stem.with_suffix(".log.jsonl"), "".join(self.log_lines[k]).encode())
        if self.checkpoint_path is None:
            return
        if self.trainer.done:
            self.checkpoint_path.unlink(missing_ok=True)
            return
        extra = {
            "identity": self.identity(),
            "source": [env.source.state_dict() for env in self.trainer.envs],
            "current": [int(e.reference.label["track_id"]) for e in self.trainer.envs],
            "log_lines": self.log_lines[0],
            "steps": self.steps,
            "wall_seconds": wall,
        }
        save_checkpoint(self.checkpoint_path, self.trainer, extra)

    # ------------------------------------------------------------------------------- run
    def run(self, on_step: Callback | None = None) -> list[TrainResult]:
        """Pretrain (a fresh run), train until every member has stopped, and return each
        route's model."""
        self.started = time.perf_counter()
        if not self.resumed_from:
            self.trainer.pretrain(demonstrations(self.envs))
        while not self.trainer.done:
            logs = self.trainer.step()
            self.steps += 1
            for log in logs:
                row = {**log.__dict__, "wall_seconds": round(self.elapsed(), 3)}
                self.log_lines[self.route_of(log.member)].append(json.dumps(row) + "\n")
            if logs:
                self.save({self.route_of(log.member) for log in logs})
            if on_step is not None:
                on_step(self.trainer, logs)
        wall = self.elapsed()
        results = []
        for k, route in enumerate(self.routes):
            nets = self.networks(k)
            model = route.stem.with_suffix(".pt") if route.stem else None
            card = self.card(k, nets, wall)
            results.append(
                TrainResult(model, card, nets, self.config, self.sources[k].space.corridor,
                            self.history(k), wall, self.steps, self.resumed_from)
            )  # fmt: skip
        return results


CHECKPOINT_ENTRIES = ("identity", "source", "current", "log_lines", "steps", "wall_seconds")
"""What `EnsembleRun.save` adds to the trainer's state in a checkpoint."""


def check_identity(path: Path, theirs: Any, mine: dict[str, Any]) -> None:
    """Refuse a checkpoint of another run (`EnsembleRun.identity`), saying what differs."""
    if not isinstance(theirs, dict) or any(theirs.get(k) != mine[k] for k in RUN_IDENTITY):
        raise UserError(
            f"{path} belongs to another run (cluster, seed or training tracks differ); use the "
            "same --seed/--max-tracks/--data, or train without --resume"
        )
    if theirs.get("lane") is None:  # a checkpoint from before lane settings were recorded
        return
    lane = {**LaneConfig().to_dict(), **theirs["lane"]}  # what it predates ran as the default
    if lane != mine["lane"]:
        keys = [k for k in {**lane, **mine["lane"]} if lane.get(k) != mine["lane"].get(k)]
        raise UserError(
            f"the checkpoint {path} was written with --lane {lane_options(lane, keys)}, this run "
            f"has {lane_options(mine['lane'], keys)}: pass the same --lane options or drop "
            "--resume"
        )


RUN_IDENTITY = ("cluster", "seed", "track_ids")
"""The entries of `EnsembleRun.identity` that say which run (the lane: how it was trained)."""


def lane_options(lane: dict[str, Any], keys: Sequence[str]) -> str:
    """`fourier=6 pretrain=50`: the lane settings `keys` as `--lane` takes them."""

    def shown(value: Any) -> str:
        if isinstance(value, bool):
            return str(value).lower()
        return f"{value:g}" if isinstance(value, float) else str(value)

    return " ".join(f"{k}={shown(lane.get(k))}" for k in keys)


def train_lanes(
    routes: Sequence[LaneRoute], on_step: Callback | None = None, first_member: int = 0
) -> list[TrainResult]:
    """Train one DATI model per route as one batched ensemble (see `EnsembleRun`; seeds from
    member `first_member` on); the models' cards are not calibrated yet
    (`aisdati.detectors.dati`)."""
    torch.set_num_threads(1)  # small batched networks: one thread is fastest (3x on 2 cores)
    run = EnsembleRun(routes, first_member)
    run.resume()
    return run.run(on_step)


def train_ais(settings: TrainSettings, on_step: Callback | None = None) -> TrainResult:
    """Train one DATI model on a cluster's tracks of the ingest folder (an ensemble of one
    route); writes <out>/<stem>.pt, .json (the card) and .log.jsonl after every episode, and the
    checkpoint <stem>.ckpt that `resume` continues from."""
    tracks, data = training_set(settings)
    return train_lanes([LaneRoute(settings, tracks, data)], on_step)[0]
