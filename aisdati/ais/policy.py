"""A learnt AIS policy (DATI's forward actor, or BC) and the two ways it judges a track.

Both read the same observation as in training, (position scaled by the model's box, step index
t; with `goal=true`, the judged track's own last report as the goal), and decide (SOG, COG, dt)
scaled into [-1, 1], which the spherical rule turns into a move.

- **rollout** (the paper's score, section 6.2): K free rollouts from the track's first point,
  for as many steps as the track has; the score is the best rollout's mean great-circle distance
  along the DTW warping path (metres). A free rollout compounds every small error of the policy,
  so this mostly measures how well the model generates whole tracks.
- **step** (teacher-forced, a departure from the paper): at every real report s_t, K decisions
  are drawn at (s_t, t), moved by the rule over the track's *real* time step, and the error is the
  great-circle distance from the predicted position to the real s_{t+1}; the best of the K is the
  step error (the model as a one-step predictive density, as likelihood-based AIS detectors do).
  Each draw takes fresh latent noise.
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

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from aisdati.ais.space import AISSpace
from aisdati.dtw import batch_mean_dtw_m
from aisdati.geo import haversine_m
from aisdati.model.dati import DATIConfig
from aisdati.model.networks import DATINetworks, one_member
from aisdati.model.noise import NoiseProcess
from aisdati.model.rules import SphericalRule

Act = Callable[[np.ndarray], np.ndarray]
"""observations [N, state + 1] (`AISSpace.features`, then the time input) -> scaled decisions
[N, 3]."""
MakeAct = Callable[[int, int, bool], Act]
"""(batch size N, seed, temporal noise) -> a stateful batched policy; with temporal noise off,
each call draws independent latent noise (one-step scoring)."""


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
        self,
        positions: np.ndarray,
        previous: np.ndarray,
        dts: np.ndarray,
        t: np.ndarray,
        horizon: np.ndarray,
        goals: np.ndarray | None = None,
    ) -> np.ndarray:
        state = self.space.features(positions, previous, dts, goals)
        time = self.space.time_input(t, horizon)
        return np.concatenate([state, np.asarray(time)[:, None]], axis=1).astype(np.float32)

    # ---------------------------------------------------------------- free rollouts
    def generate(
        self,
        starts: np.ndarray,
        horizons: np.ndarray,
        rollouts: int,
        seed: int = 0,
        reach: float = 1.0,
        goals: np.ndarray | None = None,
    ) -> np.ndarray:
        """K rollouts from each start in one batch: positions [N * K, max steps + 1, 2],
        rollout k of start i at row i * K + k; rows past their last step hold their last
        position. Each runs `reach` x its horizon steps (rounded up); the time input still
        counts towards the horizon, so the first `horizon` steps are the same whatever the
        reach. A step that would leave the region sticks or slides (`AISSpace.resolve`).
        `goals` [N, 2]: where each start's track is bound (goal-conditioned models)."""
        with one_thread():
            n = len(starts) * rollouts
            pos = np.repeat(np.asarray(starts, np.float64), rollouts, axis=0)
            bound = None if goals is None else np.repeat(np.asarray(goals), rollouts, axis=0)
            prev, last_dt = pos.copy(), np.zeros(n)
            limit = np.repeat(np.asarray(horizons), rollouts)
            runs = np.ceil(limit * reach).astype(int)
            steps = int(np.max(runs))
            out = np.empty((n, steps + 1, 2))
            out[:, 0] = pos
            act = self.make_act(n, seed, True)
            for t in range(steps):
                action = act(self.observe(pos, prev, last_dt, np.full(n, t), limit, bound))
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
        track's start). The K scored rollouts come first and are drawn as without a lane, so
        the rollout score does not depend on L; the other L - K come from a stream of their
        own."""
        starts = np.array([t[0] for t in tracks])
        goals = np.array([t[-1] for t in tracks])
        horizons = np.array([len(t) - 1 for t in tracks])
        paths = self.generate(starts, horizons, rollouts, seed, reach, goals)
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
            stream = int(np.random.SeedSequence([seed, 1]).generate_state(1)[0])
            extra = self.generate(starts, horizons, more, stream, reach, goals)
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
        ahead: int = 1,
        chunk: int = 200_000,
    ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per track, every draw's prediction error (metres) `ahead` reports on from each real
        report that has one ([n - h, K] for n reports, h = min(ahead, n - 1), K `draws`): the
        policy moved h times from the real report, each move over the real time step, its own
        moves feeding its state; and the predicted positions [n - h, K, 2]. Row i predicts
        report i + h. With `ahead` 1 these are the one-step errors."""
        spans = [min(ahead, len(p) - 1) for p in tracks]
        here, prev, last, there, step_dt, t0, horizon, goal = ([] for _ in range(8))
        for p, d, h in zip(tracks, dts, spans, strict=True):
            m = len(p) - h  # anchors 0 .. n - h - 1
            here.append(p[:m])
            prev.append(np.vstack([p[:1], p[: m - 1]]))
            last.append(np.r_[0.0, d[: m - 1]])
            there.append(p[h:])
            step_dt.append(np.stack([d[k : k + m] for k in range(h)], axis=1))
            t0.append(np.arange(m))
            horizon.append(np.full(m, len(p) - 1))
            goal.append(np.broadcast_to(p[-1], (m, 2)))
        h_max = max(spans, default=1)
        rows = [
            np.concatenate(x).repeat(draws, axis=0)
            for x in (here, prev, last, there, t0, horizon, goal)
        ]
        pos, before, last_dt, target, t, limit, bound = rows
        # the first move's observations are the same for every draw: computed once per report
        first = self.observe(*(np.concatenate(x) for x in (here, prev, last, t0, horizon, goal)))
        first = first.repeat(draws, axis=0)
        dt = np.concatenate([np.pad(x, ((0, 0), (0, h_max - x.shape[1]))) for x in step_dt])
        dt = dt.repeat(draws, axis=0)
        moves = np.concatenate([np.full(len(x), h) for x, h in zip(here, spans, strict=True)])
        moves = moves.repeat(draws)
        err = np.empty(len(pos))
        pred = np.empty((len(pos), 2))
        chunk = max(draws, chunk - chunk % draws)  # draw d of each report: same member
        with one_thread():
            for lo in range(0, len(pos), chunk):
                sl = slice(lo, lo + chunk)
                act = self.make_act(len(pos[sl]), seed + lo, False)
                p, q, w = pos[sl], before[sl], last_dt[sl]
                for k in range(int(moves[sl].max(initial=0))):
                    obs = (
                        first[sl]
                        if k == 0
                        else self.observe(p, q, w, t[sl] + k, limit[sl], bound[sl])
                    )
                    decision = self.rule.decision_scaler.unscale(np.clip(act(obs), -1.0, 1.0))
                    decision[:, 2] = dt[sl, k]
                    live = (k < moves[sl])[:, None]
                    p, q, w = (
                        np.where(live, self.rule.step(p, decision), p),
                        np.where(live, p, q),
                        decision[:, 2],
                    )
                pred[sl] = p
                err[sl] = haversine_m(p[:, 0], p[:, 1], target[sl, 0], target[sl, 1])
        cuts = np.cumsum([len(p) - h for p, h in zip(tracks, spans, strict=True)])[:-1]
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


def member_rows(n: int, members: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Which of n batch rows each member of an ensemble acts on: an [M, width] grid of row
    indices (clamped to the batch) and its mask of real rows. Row i is member i mod M's (member
    m's rows m, m + M, ... as row m of an [M, ceil(n / M)] grid: K draws spread over the
    members, each computing its own rows only). One member acts on every row through a
    one-member copy of the networks (`aisdati.model.networks.one_member`), M = 1."""
    width = -(-n // members)
    grid = torch.arange(members)[:, None] + members * torch.arange(width)[None]
    return grid.clamp(max=n - 1), grid < n


def member_decisions(out: torch.Tensor, grid: torch.Tensor, valid: torch.Tensor) -> np.ndarray:
    """The n rows' decisions [n, k] from an ensemble's [M, width, k] over `member_rows`."""
    decided = torch.empty(int(valid.sum()), out.shape[-1], dtype=out.dtype)
    decided[grid[valid]] = out[valid]
    return decided.numpy()


def dati_act(nets: DATINetworks, config: DATIConfig, member: int | None = None) -> MakeAct:
    """DATI's forward actor as a batched policy: member `member` of the ensemble, or with None
    every member in turn (`member_rows`). Each row draws its own latent noise, Gaussian or
    (with temporal noise) Ornstein-Uhlenbeck."""
    if member is not None:
        nets = one_member(nets, member)
    members = nets.forward_actor.out.weight.shape[0]  # live members (stopped ones leave)
    device = nets.device

    def make(n: int, seed: int, temporal: bool) -> Act:
        process = config.noise_process if temporal else NoiseProcess("gaussian")
        noise = config.latent_noise([torch.Generator().manual_seed(int(seed))], [process], rows=n)
        grid, valid = member_rows(n, members)

        def act(obs: np.ndarray) -> np.ndarray:
            eta = noise.sample()[0]
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
