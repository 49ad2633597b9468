"""A learnt AIS policy (DATI's forward actor, or BC) and the two ways it judges a track.

Both read the same observation as in training, (position scaled by the model's box, step index
t), and decide (SOG, COG, dt) scaled into [-1, 1], which the spherical rule turns into a move.

Every draw is keyed (`Draws`): its latent noise and the ensemble member that acts on it follow
from the run's seed, the judged track's own reports and the draw's index alone, so a track's
scores are the same whatever other tracks are judged with it (`aisdati.model.noise.KeyedNoise`).

- **rollout** (the paper's score, section 6.2): K free rollouts from the track's first point,
  for as many steps as the track has; the score is the best rollout's mean great-circle distance
  along the DTW warping path (metres). A free rollout compounds every small error of the policy,
  so this mostly measures how well the model generates whole tracks.
- **step** (teacher-forced, a departure from the paper): at every real report s_t, K decisions
  are drawn at (s_t, t), moved by the rule over the track's *real* time step, and the error is the
  great-circle distance from the predicted position to the real s_{t+1}; the best of the K is the
  step error (the model as a one-step predictive density, as likelihood-based AIS detectors do).
  Each draw takes its own latent noise. The area's BC also judges each draw against where the
  report's own SOG and COG put the vessel (`reported_next`, `ScoreSettings.reported_motion`).
- **lane** (a departure from the paper): each report's distance to the nearest point of any of
  the K free rollouts, whatever its timing: whether the track stays where the traffic the model
  generates from its start goes. Best-of-K DTW judges a track against one rollout; a lane of
  K rollouts also covers the spread of normal traffic across the channel. The lane's rollouts
  run `ScoreSettings.lane_reach` (2) x the track's number of steps: the lane is where the
  model's traffic goes from the track's start, not how far it gets in the track's number of
  steps, so a model whose pace is off by up to half still reaches the track's end.

Step and lane scores aggregate a track's per-report distances with `aisdati.detectors.base.
tail_mean`, so a short jump or loiter counts as much as a long detour, whatever the length.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from aisdati.ais.space import AISSpace
from aisdati.dtw import batch_mean_dtw_m
from aisdati.geo import haversine_m, spherical_step
from aisdati.model.dati import DATIConfig
from aisdati.model.networks import DATINetworks, one_member
from aisdati.model.noise import GOLDEN, KeyedNoise, NoiseProcess, mix64
from aisdati.model.rules import SphericalRule


@dataclass(frozen=True)
class Draws:
    """What each row of a batch is: draw `index` of the track keyed `track` (`track_keys`).
    Its noise follows from the pair and its member from `track` and `draw`, never from the
    row's place in the batch."""

    track: np.ndarray
    """[n] uint64: the key of the row's track."""
    index: np.ndarray
    """[n] int64: which of its track's draws the row's noise is."""
    draw: np.ndarray
    """[n] int64: which of its track's K draws the row is (sets its member)."""

    @property
    def keys(self) -> np.ndarray:
        """[n] uint64 noise keys: the track's key and the draw's index mixed."""
        with np.errstate(over="ignore"):
            return mix64(self.track + self.index.astype(np.uint64) * GOLDEN)

    def members(self, count: int) -> np.ndarray:
        """[n] which of `count` ensemble members acts on each row: a track's draws in turn,
        starting at a member its key picks."""
        return ((self.track % np.uint64(count)).astype(np.int64) + self.draw) % count

    def __getitem__(self, rows: slice) -> Draws:
        return Draws(self.track[rows], self.index[rows], self.draw[rows])

    def __len__(self) -> int:
        return len(self.track)


def track_keys(tracks: Sequence[np.ndarray], seed: int, stream: int = 0) -> np.ndarray:
    """[N] uint64: a key per track from the run's `seed`, a `stream` and the track's own
    positions (a track is what it reports, whatever its id or batch)."""
    out = np.empty(len(tracks), np.uint64)
    for i, positions in enumerate(tracks):
        h = hashlib.blake2b(digest_size=8, key=f"{seed}:{stream}".encode())
        h.update(np.ascontiguousarray(positions, np.float64).tobytes())
        out[i] = np.frombuffer(h.digest(), np.uint64)[0]
    return out


def draw_rows(keys: np.ndarray, draws: range) -> Draws:
    """Draws `draws` of each track keyed `keys`: draw d of track i at row i * len(draws) +
    (d - draws.start)."""
    index = np.tile(np.arange(draws.start, draws.stop, dtype=np.int64), len(keys))
    return Draws(np.repeat(np.asarray(keys, np.uint64), len(draws)), index, index)


Act = Callable[[np.ndarray], np.ndarray]
"""observations [N, state + 1] (`AISSpace.features`, then the time input) -> scaled decisions
[N, 3]."""
MakeAct = Callable[[Draws, bool], Act]
"""(what each row is, temporal noise) -> a stateful batched policy; each call draws the rows'
next latent noise, which with temporal noise follows an Ornstein-Uhlenbeck process."""


@dataclass
class AISPolicy:
    """What scoring needs of a trained AIS policy, whatever learnt it: its space (region, rule,
    view of the agent) and a batched policy."""

    space: AISSpace
    make_act: MakeAct

    @property
    def rule(self) -> SphericalRule:
        return self.space.rule

    def observe(
        self, positions: np.ndarray, previous: np.ndarray, dts: np.ndarray, t: np.ndarray
    ) -> np.ndarray:
        state = self.space.features(positions, previous, dts)
        return np.concatenate([state, np.asarray(t, np.float64)[:, None]], axis=1).astype(
            np.float32
        )

    # ---------------------------------------------------------------- free rollouts
    def generate(
        self,
        starts: np.ndarray,
        horizons: np.ndarray,
        keys: np.ndarray,
        draws: range,
        reach: float = 1.0,
    ) -> np.ndarray:
        """Rollouts `draws` from each start (keyed `keys`, `track_keys`) in one batch: positions
        [N * R, max steps + 1, 2], rollout d of start i at row i * R + (d - draws.start); rows
        past their last step hold their last position. Each runs `reach` x its horizon steps
        (rounded up). A step that would leave the region sticks or slides
        (`AISSpace.resolve`)."""
        with one_thread():
            rows = draw_rows(keys, draws)
            n = len(rows)
            pos = np.repeat(np.asarray(starts, np.float64).reshape(-1, 2), len(draws), axis=0)
            prev, last_dt = pos.copy(), np.zeros(n)
            runs = np.ceil(np.repeat(np.asarray(horizons), len(draws)) * reach).astype(int)
            steps = int(np.max(runs, initial=0))
            out = np.empty((n, steps + 1, 2))
            out[:, 0] = pos
            act = self.make_act(rows, True)
            for t in range(steps):
                action = act(self.observe(pos, prev, last_dt, np.full(n, t)))
                decision = self.rule.decision_scaler.unscale(np.clip(action, -1.0, 1.0))
                moved = self.space.resolve(pos, self.rule.step(pos, decision))
                live = t < runs
                prev = np.where(live[:, None], pos, prev)
                last_dt = np.where(live, decision[:, 2], last_dt)
                pos = np.where(live[:, None], moved, pos)
                out[:, t + 1] = pos
        return out

    def rollout_scores(
        self,
        tracks: Sequence[np.ndarray],
        rollouts: int,
        seed: int = 0,
        reach: float = 1.0,
        lane_rollouts: int | None = None,
    ) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
        """Best-of-K mean great-circle DTW (metres) of each track over its own number of
        steps, its best rollout, and all its L rollouts (`lane_rollouts`, default K) run
        `reach` x as many steps ([L, steps + 1, 2]: the lane the policy generates from the
        track's start). The K scored rollouts are draws 0 .. K - 1 of the track, the other
        L - K draws K .. L - 1, so the rollout score does not depend on L."""
        keys = track_keys(tracks, seed)
        starts = np.array([t[0] for t in tracks]).reshape(-1, 2)
        horizons = np.array([len(t) - 1 for t in tracks], np.int64)
        paths = self.generate(starts, horizons, keys, range(rollouts), reach)
        dists = batch_mean_dtw_m(
            paths,
            np.repeat(horizons + 1, rollouts),
            list(tracks),
            np.repeat(np.arange(len(tracks)), rollouts),
        ).reshape(len(tracks), rollouts)
        best = dists.argmin(axis=1)
        runs = np.ceil(horizons * reach).astype(int)
        every = [paths[i * rollouts : (i + 1) * rollouts, : r + 1] for i, r in enumerate(runs)]
        more = (lane_rollouts or rollouts) - rollouts
        if more > 0:
            extra = self.generate(starts, horizons, keys, range(rollouts, rollouts + more), reach)
            every = [
                np.concatenate([e, extra[i * more : (i + 1) * more, : r + 1]])
                for i, (e, r) in enumerate(zip(every, runs, strict=True))
            ]
        chosen = [e[b, : h + 1].copy() for e, b, h in zip(every, best, horizons, strict=True)]
        return dists[np.arange(len(tracks)), best], chosen, every

    # ------------------------------------------------------------- one-step errors
    def step_draws(
        self,
        tracks: Sequence[np.ndarray],
        dts: Sequence[np.ndarray],
        draws: int,
        seed: int = 0,
        chunk: int = 200_000,
    ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per track, every draw's one-step prediction error (metres) from each real report
        that has a next one ([n - 1, K] for n reports, K `draws`): the policy moved once from
        the real report over the real time step; and the predicted positions [n - 1, K, 2].
        Row i predicts report i + 1. Draw k of report i of a track is its draw i * K + k
        (`Draws.index`), acted on by the member of its k (`Draws.draw`)."""
        anchors = [max(len(p) - 1, 0) for p in tracks]
        keys = track_keys(tracks, seed)
        here = np.concatenate(
            [p[:m] for p, m in zip(tracks, anchors, strict=True)] + [np.empty((0, 2))]
        )
        prev = np.concatenate(
            [np.vstack([p[:1], p[: m - 1]])[:m] for p, m in zip(tracks, anchors, strict=True)]
            + [np.empty((0, 2))]
        )
        last = np.concatenate(
            [np.r_[0.0, d[: m - 1]][:m] for d, m in zip(dts, anchors, strict=True)] + [np.empty(0)]
        )
        there = np.concatenate(
            [p[1 : m + 1] for p, m in zip(tracks, anchors, strict=True)] + [np.empty((0, 2))]
        )
        step_dt = np.concatenate([d[:m] for d, m in zip(dts, anchors, strict=True)] + [np.empty(0)])
        t = np.concatenate([np.arange(m) for m in anchors] + [np.empty(0, np.int64)])
        obs = self.observe(here, prev, last, t).repeat(draws, axis=0)
        track = np.repeat(keys, np.asarray(anchors, np.int64) * draws)
        index = np.concatenate(
            [np.arange(m * draws, dtype=np.int64) for m in anchors] + [np.empty(0, np.int64)]
        )
        rows = Draws(track, index, index % draws)
        pos, target = here.repeat(draws, axis=0), there.repeat(draws, axis=0)
        dt = step_dt.repeat(draws)
        err = np.empty(len(pos))
        pred = np.empty((len(pos), 2))
        with one_thread():
            for lo in range(0, len(pos), chunk):
                sl = slice(lo, lo + chunk)
                act = self.make_act(rows[sl], False)
                decision = self.rule.decision_scaler.unscale(np.clip(act(obs[sl]), -1.0, 1.0))
                decision[:, 2] = dt[sl]
                pred[sl] = self.rule.step(pos[sl], decision)
                err[sl] = haversine_m(pred[sl, 0], pred[sl, 1], target[sl, 0], target[sl, 1])
        cuts = np.cumsum(anchors)[:-1]
        return np.split(err.reshape(-1, draws), cuts), np.split(pred.reshape(-1, draws, 2), cuts)

    def step_errors(
        self,
        tracks: Sequence[np.ndarray],
        dts: Sequence[np.ndarray],
        draws: int,
        seed: int = 0,
    ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per track, the best-of-K one-step prediction error (metres) at each report after the
        first ([n - 1] for n reports; `step_draws`), and the best predicted positions
        [n - 1, 2]."""
        return best_draws(*self.step_draws(tracks, dts, draws, seed))


def reported_next(
    positions: np.ndarray, dts: np.ndarray, sog: np.ndarray, cog: np.ndarray
) -> np.ndarray:
    """[n - 1, 2] where each report's reported motion puts the vessel at the next report's
    time: the kinematic rule (`aisdati.geo.spherical_step`) from the report over the real time
    step, at the mean of the two reports' reported velocities (as `aisdati.events.reports`
    does: exact for a vessel that turns or speeds up steadily); NaN where either lacks SOG or
    COG. The second target of a one-step prediction (`ScoreSettings.reported_motion`)."""
    course = np.radians(cog)
    east, north = sog * np.sin(course), sog * np.cos(course)
    east, north = (east[:-1] + east[1:]) / 2, (north[:-1] + north[1:]) / 2
    heading = np.degrees(np.arctan2(east, north)) % 360.0
    lon, lat = spherical_step(positions[:-1, 0], positions[:-1, 1], np.hypot(east, north),
                              heading, dts[: len(positions) - 1])  # fmt: skip
    return np.column_stack([lon, lat])


def best_draws(
    errors: Sequence[np.ndarray], predicted: Sequence[np.ndarray]
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per track, of `step_draws`' K draws at each report, the smallest error ([n - 1]) and
    its predicted position ([n - 1, 2])."""
    best = [e.argmin(axis=1) for e in errors]
    return (
        [e[np.arange(len(b)), b] for e, b in zip(errors, best, strict=True)],
        [q[np.arange(len(b)), b] for q, b in zip(predicted, best, strict=True)],
    )


def member_rows(members_of: np.ndarray, members: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Which of n batch rows each member of an ensemble acts on, from each row's member
    (`Draws.members`): an [M, width] grid of row indices (padded with row 0) and its mask of
    real rows. One member acts on every row through a one-member copy of the networks
    (`aisdati.model.networks.one_member`), M = 1."""
    mine = [np.flatnonzero(members_of == m) for m in range(members)]
    width = max((len(r) for r in mine), default=0)
    grid = np.zeros((members, width), np.int64)
    valid = np.zeros((members, width), bool)
    for m, rows in enumerate(mine):
        grid[m, : len(rows)], valid[m, : len(rows)] = rows, True
    return torch.as_tensor(grid), torch.as_tensor(valid)


def member_decisions(out: torch.Tensor, grid: torch.Tensor, valid: torch.Tensor) -> np.ndarray:
    """The n rows' decisions [n, k] from an ensemble's [M, width, k] over `member_rows`."""
    decided = torch.empty(int(valid.sum()), out.shape[-1], dtype=out.dtype)
    decided[grid[valid]] = out[valid]
    return decided.numpy()


def dati_act(nets: DATINetworks, config: DATIConfig, member: int | None = None) -> MakeAct:
    """DATI's forward actor as a batched policy: member `member` of the ensemble, or with None
    every member on its rows (`Draws.members`). Each row draws its own keyed latent noise,
    Gaussian or (with temporal noise) Ornstein-Uhlenbeck."""
    if member is not None:
        nets = one_member(nets, member)
    members = nets.forward_actor.out.weight.shape[0]  # live members (stopped ones leave)
    device = nets.device

    def make(rows: Draws, temporal: bool) -> Act:
        process = config.noise_process if temporal else NoiseProcess("gaussian")
        dim = config.network.latent_dim
        noise = KeyedNoise(rows.keys, dim, config.noise_sigma, config.ou_theta, process)
        grid, valid = member_rows(rows.members(members), members)

        def act(obs: np.ndarray) -> np.ndarray:
            eta = noise.sample()
            out = nets.decide(torch.as_tensor(obs)[grid].to(device), eta[grid].to(device)).cpu()
            return member_decisions(out, grid, valid)

        return act

    return make


class one_thread:
    """Small batched matmuls: extra torch threads cost 10x on 2 busy cores."""

    def __enter__(self) -> None:
        self.threads = torch.get_num_threads()
        torch.set_num_threads(1)

    def __exit__(self, *exc: Any) -> None:
        torch.set_num_threads(self.threads)
