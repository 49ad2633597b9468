"""The reference source of DATI on real AIS tracks: the cluster's (or route's) tracks, one per
episode, cycling through a shuffled list so that N episodes over N tracks see every track once
(the paper: 170 episodes, 170 tracks), in the space the agent sees and moves in (`AISSpace`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from aisdati.ais.space import AISSpace, LaneConfig
from aisdati.model.env import Reference, ReferenceSource, TrajectoryImitationEnv
from aisdati.tracks.store import Track

EPSILON_M = 500.0
"""The paper's ε for AIS, in metres (mean great-circle distance along the warping path)."""


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
        return float(self.max_steps)

    def contains(self, position: np.ndarray) -> bool:
        return bool(self.space.contains(position))

    def resolve(self, position: np.ndarray, proposed: np.ndarray) -> np.ndarray:
        return self.space.resolve(position, proposed)

    def features(self, positions: np.ndarray, previous: np.ndarray, dts: np.ndarray) -> np.ndarray:
        return self.space.features(positions, previous, dts)

    def time_input(self, t: np.ndarray, horizon: int) -> np.ndarray:
        return np.asarray(t, np.float64)

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
        """Continue the episode order of `state_dict` (it comes from a checkpoint: an order
        that is not one of these references is a `ValueError`)."""
        order, position = [int(i) for i in state["order"]], int(state["position"])
        if order and sorted(order) != list(range(len(self.references))):
            raise ValueError(f"episode order {order} is not one of {len(self.references)} tracks")
        if not 0 <= position <= len(order):
            raise ValueError(f"episode position {position} is outside its order of {len(order)}")
        self.order, self.position = order, position


def make_env(source: AISTrackSource, epsilon: float = EPSILON_M) -> TrajectoryImitationEnv:
    return TrajectoryImitationEnv(source, epsilon=epsilon)


def fit_space(tracks: Sequence[Track], config: LaneConfig | None = None) -> AISSpace:
    """The region, rule and view that fit the training tracks (`AISSpace.fit`)."""
    positions, dts = [t.positions for t in tracks], [t.dts for t in tracks]
    return AISSpace.fit(positions, dts, config or LaneConfig())


def build_source(tracks: Sequence[Track], config: LaneConfig | None = None) -> AISTrackSource:
    return AISTrackSource([track_reference(t) for t in tracks], fit_space(tracks, config))
