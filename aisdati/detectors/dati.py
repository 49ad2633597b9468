"""`dati`: the paper's method. The forward actor of a DATI model trained on the group's tracks
(`aisdati.ais.training`, every route of an area as one batched ensemble) judges a track by how
far it strays from where the actor would sail (`aisdati.detectors.policy`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from aisdati.ais.card import DataCard, ModelCard
from aisdati.ais.policy import Act, Draws, dati_act
from aisdati.ais.training import (
    LaneRoute,
    TrainResult,
    TrainSettings,
    crossfit_folds,
    train_lanes,
)
from aisdati.detectors.base import Detector
from aisdati.detectors.policy import PolicyDetector, saved_corridor
from aisdati.detectors.scoring import ScoreSettings
from aisdati.errors import UserError
from aisdati.model.dati import DATIConfig
from aisdati.model.networks import DATINetworks
from aisdati.model.persistence import load_networks, network_bytes, network_meta
from aisdati.model.trainer import Callback
from aisdati.tracks.store import Track


class DATIDetector(PolicyDetector):
    method = "dati"
    model_suffix = ".pt"

    def __init__(
        self,
        settings: TrainSettings | None = None,
        how: ScoreSettings | None = None,
        name: str | None = None,
    ):
        super().__init__(settings, how, name)
        self.nets: DATINetworks | None = None
        self.config = DATIConfig()

    @classmethod
    def model_name(cls, cluster: str) -> str:
        """`<cluster>`, as before detectors had names."""
        return cluster

    def fit(
        self,
        tracks: Sequence[Track],
        data: DataCard | None = None,
        on_step: Callback | None = None,
    ) -> DATIDetector:
        """Train DATI on the tracks (an ensemble of one route; with an `out_dir` in the
        settings, the model files are written after every episode and `resume` continues a
        checkpoint), then score them to calibrate."""
        route = LaneRoute(self.settings, list(tracks), self.describe(tracks, data))
        (result,) = train_lanes([route], on_step)
        self.take(result, route.tracks)
        return self

    @classmethod
    def members(cls, settings: TrainSettings) -> int:
        return settings.lane.members

    @classmethod
    def fit_routes(
        cls,
        settings: Sequence[TrainSettings],
        training_sets: Sequence[tuple[list[Track], DataCard]],
        how: ScoreSettings | None = None,
        on_step: Callback | None = None,
        first_member: int = 0,
    ) -> list[Detector]:
        """Every route as one batched ensemble (`aisdati.ais.training.EnsembleRun`)."""
        routes = [
            LaneRoute(s, tracks, data)
            for s, (tracks, data) in zip(settings, training_sets, strict=True)
        ]
        detectors: list[Detector] = []
        for route, result in zip(routes, train_lanes(routes, on_step, first_member), strict=True):
            det = cls(route.settings, how)
            det.take(result, route.tracks)
            detectors.append(det)
        return detectors

    def take(self, result: TrainResult, tracks: Sequence[Track]) -> None:
        """Become the model `result` trained on `tracks`, and calibrate it on them."""
        self.nets, self.config, self.corridor = result.networks, result.config, result.corridor
        self.to_device(self.settings.device)  # calibrate where it trained
        self.card, self.resumed_from = result.card, result.resumed_from
        self.card.training.finished = True
        lane = self.card.lane_config
        folds = crossfit_folds(tracks, lane.members, self.card.seed) if lane.crossfit else None
        self.calibrate(tracks, folds=folds)

    def make_act(self, rows: Draws, temporal: bool, member: int | None = None) -> Act:
        return dati_act(self.trained(), self.config, member)(rows, temporal)

    def to_device(self, device: str) -> None:
        self.trained().to(device)

    def trained(self) -> DATINetworks:
        if self.nets is None:
            raise UserError("the dati detector is not fitted: fit it or load one")
        return self.nets

    def save(self, stem: Path) -> None:
        nets = self.trained()
        self.write_model(stem, {".pt": network_bytes(nets)}, network_meta(nets, self.config))

    @classmethod
    def from_files(cls, stem: Path, card: ModelCard) -> DATIDetector:
        nets, config, _ = load_networks(stem)
        members = card.lane_config.members
        if nets.members != members or nets.decision_dim != 3:
            raise UserError(f"{stem}: expected a model of {members} member(s) with 3 decisions")
        det = cls(name=stem.name)
        det.card, det.nets, det.config = card, nets, config
        det.corridor = saved_corridor(stem, card)
        return det
