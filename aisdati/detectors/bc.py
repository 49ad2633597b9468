"""`bc`: behavioural cloning (a Gaussian policy on position and step index, the self-test's BC,
`aisdati.model.bc`), rolled out and scored exactly like DATI: the learnt baseline DATI has to
beat. One model; with cross-fitting (`LaneConfig.crossfit`, the `area` preset's) one member per
fold as DATI's, each fitted to the other folds and calibrating its own, so that its threshold
comes from tracks it did not fit: without folds, fitted to every training track, BC flagged
31-35 % of Kitimat's normal later tracks forward in time (docs/results/forward.md)."""

from __future__ import annotations

import io
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from aisdati.ais.card import DataCard, ModelCard, NetworkCard, TrainingReport
from aisdati.ais.policy import Act, Draws, member_decisions, member_rows
from aisdati.ais.source import build_source, make_env
from aisdati.ais.training import (
    TrainSettings,
    base_card,
    check_crossfit,
    crossfit_folds,
    member_seeds,
    member_sources,
)
from aisdati.detectors.policy import PolicyDetector, saved_corridor
from aisdati.detectors.scoring import ScoreSettings
from aisdati.errors import UserError
from aisdati.model.bc import BCConfig, BCPolicy, BCTrainer, sample_decisions
from aisdati.model.networks import one_member
from aisdati.model.noise import KeyedNoise
from aisdati.model.persistence import load_weights
from aisdati.model.readers import first_line
from aisdati.model.trainer import Callback
from aisdati.tracks.store import Track


class BCDetector(PolicyDetector):
    method = "bc"

    def __init__(
        self,
        settings: TrainSettings | None = None,
        how: ScoreSettings | None = None,
        name: str | None = None,
    ):
        super().__init__(settings, how, name)
        self.bc: BCPolicy | None = None

    def fit(
        self,
        tracks: Sequence[Track],
        data: DataCard | None = None,
        on_step: Callback | None = None,
    ) -> BCDetector:
        """Train BC for `settings.episodes` episodes (its training reports no steps: `on_step`
        is DATI's), then score the training tracks to calibrate."""
        t0 = time.perf_counter()
        torch.set_num_threads(1)
        lane = self.settings.lane
        # a card's seeds number its members: one model, or one per cross-fitting fold
        members = lane.members if lane.crossfit else 1
        config = replace(lane, members=members)
        check_crossfit(config, {self.settings.cluster: len(tracks)})
        source = build_source(tracks, config)
        self.card = base_card("bc", self.settings, source.space, self.describe(tracks, data))
        folds = (
            crossfit_folds(tracks, members, self.settings.seed)
            if lane.crossfit
            else np.full(len(tracks), -1)
        )
        trainer = BCTrainer(
            [make_env(s) for s in member_sources(source, folds, members)],
            member_seeds(self.settings.seed, members),
            BCConfig(episodes=self.settings.episodes),
        )
        self.bc = trainer.train()
        self.card.training = TrainingReport(
            episodes_run=trainer.episode[0],
            finished=True,
            details={"final_loss": float(trainer.losses[-1][0])},
        )
        self.card.networks = NetworkCard(seeds=self.bc.seeds, config=self.bc.cfg.to_dict())
        self.corridor = source.space.corridor
        self.calibrate(tracks, folds=folds if lane.crossfit else None)
        self.card.training.wall_seconds = time.perf_counter() - t0
        return self

    def make_act(self, rows: Draws, temporal: bool, member: int | None = None) -> Act:
        """BC's Gaussian policy, member `member` (a one-member copy, `one_member`) or every
        member on its rows (`Draws.members`); each row's standard normal draws are keyed
        (`aisdati.model.noise.KeyedNoise`), so they do not depend on its batch."""
        del temporal  # BC's draws are independent from step to step
        policy = self.trained()
        acting = policy if member is None else one_member(policy, member)
        count = len(acting.seeds)
        grid, valid = member_rows(rows.members(count), count)
        noise = KeyedNoise(rows.keys, 3)

        def act(obs: np.ndarray) -> np.ndarray:
            eta = noise.sample()[grid]
            out = torch.as_tensor(sample_decisions(acting, obs[grid.numpy()], lambda _: eta))
            return member_decisions(out, grid, valid)

        return act

    def trained(self) -> BCPolicy:
        if self.bc is None:
            raise UserError("the bc detector is not fitted: fit it or load one")
        return self.bc

    def save(self, stem: Path) -> None:
        buf = io.BytesIO()
        torch.save(self.trained().state_dict(), buf)
        self.write_model(stem, {".pt": buf.getvalue()})

    @classmethod
    def from_files(cls, stem: Path, card: ModelCard) -> BCDetector:
        assert card.networks is not None  # a bc card has them (`ModelCard.from_dict`)
        try:  # the card's sizes are bounded (`ModelCard.from_dict`), its other entries not
            cfg = BCConfig.from_dict(card.networks.config)
            policy = BCPolicy(card.space().state_dim, 3, cfg, card.networks.seeds)
        except (KeyError, TypeError, ValueError, RuntimeError) as exc:
            raise UserError(f"cannot load model {stem}: {first_line(exc)}") from None
        load_weights(policy, stem.with_suffix(".pt"))
        det = cls(name=stem.name)
        det.card, det.bc, det.corridor = card, policy, saved_corridor(stem, card)
        return det
