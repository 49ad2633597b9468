"""What the detectors that judge tracks with a learnt policy share: `dati` (the paper's) and `bc`.

Both score the same ways (`aisdati.ais.policy`): free rollouts (`rollout`, the paper's),
teacher-forced one-step errors (`step`), the distance to the lane of the K rollouts (`lane`), or
`both`: the rollout and step scores, each divided by the median of the training tracks' own
scores of that kind, summed, so neither dominates by its unit of scale (a track as typical as
the median training track scores 2). The step profile stands for `both` on maps.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from aisdati.ais.card import ModelCard
from aisdati.ais.corridor import Corridor
from aisdati.ais.policy import Act, AISPolicy
from aisdati.ais.space import AISSpace
from aisdati.detectors.base import Detector
from aisdati.detectors.scoring import Scores, ScoreSettings, tail_mean
from aisdati.dtw import matched_distances
from aisdati.errors import UserError
from aisdati.geo import lane_distances
from aisdati.tracks.store import Track


class PolicyDetector(Detector):
    """A detector built on an `AISPolicy`; subclasses say how the policy acts."""

    lane_settings = ("lane_course_km", "lane_traffic")

    def policy(self) -> AISPolicy:
        return AISPolicy(AISSpace.from_card(self.card, self.corridor), self.make_act)

    @abstractmethod
    def make_act(self, n: int, seed: int, temporal: bool) -> Act:
        """The policy for a batch of n rows (`aisdati.ais.policy.MakeAct`)."""

    def score_tracks(
        self, tracks: Sequence[Track], how: ScoreSettings, also: Sequence[str]
    ) -> Scores:
        policy = self.policy()
        positions = [t.positions for t in tracks]
        wanted = {how.score, *also}
        if "both" in wanted:
            wanted |= {"rollout", "step"}
        parts: dict[str, np.ndarray] = {}
        profiles: dict[str, list[np.ndarray]] = {}
        evidence: dict[str, list[np.ndarray]] = {}
        if wanted & {"rollout", "lane"}:
            reach = how.lane_reach if "lane" in wanted else 1.0
            lane = how.lane_rollouts if "lane" in wanted else how.rollouts
            parts["rollout"], best, every = policy.rollout_scores(
                positions, how.rollouts, how.seed, reach, lane
            )
            evidence["rollout"] = evidence["lane"] = best
            if "rollout" in wanted:
                profiles["rollout"] = [
                    matched_distances(p, b) for p, b in zip(positions, best, strict=True)
                ]
        if "lane" in wanted:
            traffic = self.traffic(policy, how) if how.lane_traffic else []
            profiles["lane"] = [
                lane_distances(p, [*e, *traffic], how.lane_course_km * 1000.0)
                for p, e in zip(positions, every, strict=True)
            ]
            parts["lane"] = np.array([tail_mean(d, how.tail) for d in profiles["lane"]])
        if "step" in wanted:
            errors, predicted = policy.step_errors(
                positions, [t.dts for t in tracks], how.rollouts, how.seed
            )
            parts["step"] = np.array([tail_mean(e, how.tail) for e in errors])
            profiles["step"] = [np.concatenate([[0.0], e]) for e in errors]
            evidence["step"] = [
                np.vstack([p[:1], q]) for p, q in zip(positions, predicted, strict=True)
            ]
        if "both" in wanted:
            cal = self.card.calibration
            if not cal.get("rollout") or not cal.get("step"):
                raise UserError(f"model {self.name} has no calibration scores: retrain it")
            parts["both"] = sum(parts[k] / float(np.median(cal[k])) for k in ("rollout", "step"))
            profiles["both"], evidence["both"] = profiles["step"], evidence["rollout"]
        return Scores(
            np.asarray(parts[how.score], np.float64),
            profiles[how.score],
            evidence[how.score],
            parts,
        )

    def traffic(self, policy: AISPolicy, how: ScoreSettings) -> list[np.ndarray]:
        """One rollout from each training track's start, of the training tracks' mean number
        of steps times the lane's reach: where the model's traffic goes, shared by every
        track's lane, so a track that starts off the lane and joins it is judged against the
        lane it joins, not only against where the policy goes from its odd start."""
        starts = self.start_points
        steps = max(1, round(self.card.data.points / len(starts)) - 1)
        stream = int(np.random.SeedSequence([how.seed, 2]).generate_state(1)[0])
        paths = policy.generate(starts, np.full(len(starts), steps), 1, stream, how.lane_reach)
        return list(paths)

    def calibrate(self, tracks: Sequence[Track], how: ScoreSettings | None = None) -> None:
        """Score the training tracks every way; `threshold` and `both` read these."""
        how = how or self.how
        parts = self.score(tracks, replace(how, score="rollout"), also=("step", "lane")).parts
        cal = {k: [round(float(v), 2) for v in parts[k]] for k in ("rollout", "step", "lane")}
        both = sum(np.asarray(cal[k]) / np.median(cal[k]) for k in ("rollout", "step"))
        self.card.calibration = {**cal, "both": [round(float(v), 4) for v in both]}
        self.card.calibrated_with = how.calibrated_with()


def saved_corridor(stem: Path, card: ModelCard) -> Corridor | None:
    """The corridor saved beside a model trained with `region="corridor"`."""
    if card.lane_config.region != "corridor":
        return None
    return Corridor.from_file(stem.with_suffix(".corridor.npz"))
