"""What the detectors that judge tracks with a learnt policy share: `dati` (the paper's) and `bc`.

Both score the same ways (`aisdati.ais.policy`): free rollouts (`rollout`, the paper's),
teacher-forced one-step errors (`step`, metres; `steprate`, each over its report interval, m/s),
the distance to the lane of the K rollouts (`lane`), or `both`, `steplane` and `steptraffic`
(`RATIO_SCORES`): two of those, each divided by the median of the training tracks' own scores of
that kind, summed; `traffic` is the distance to the training tracks themselves, which a policy
keeps beside its networks (`aisdati.detectors.traffic`, as `nearest` keeps them). The step
profile stands for the sums on maps. Models whose cards record where their training tracks end
also score `od` and `area` (`aisdati.detectors.od`): the lane score plus how much rarer the
track's (start, end) pair is than the training tracks'.

A goal-conditioned model's lane traffic (`ScoreSettings.lane_traffic`) is that of the training
tracks bound the same way: starting and ending within `near_km` of the track's own start and end.
All of an area's traffic would make every lane of the area count as the track's lane.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from aisdati.ais import RATIO_SCORES, SCORE_UNITS, STEP_SCORES
from aisdati.ais.card import ModelCard
from aisdati.ais.corridor import Corridor
from aisdati.ais.policy import Act, AISPolicy, best_draws
from aisdati.ais.space import AISSpace
from aisdati.detectors.base import Detector
from aisdati.detectors.od import (
    area_scores,
    od_distances,
    od_pairs_m,
    stepod_scores,
    track_ends,
)
from aisdati.detectors.scoring import (
    Scores,
    ScoreSettings,
    error_rates,
    error_surprises,
    ratio_sum,
    tail_mean,
)
from aisdati.detectors.traffic import Traffic
from aisdati.dtw import matched_distances
from aisdati.errors import UserError
from aisdati.geo import lane_distances
from aisdati.outdir import atomic_write_bytes
from aisdati.tracks.store import Track


class PolicyDetector(Detector):
    """A detector built on an `AISPolicy`; subclasses say how the policy acts."""

    lane_settings = ("lane_course_km", "lane_traffic")
    training_tracks: Traffic | None = None
    """The training tracks (`calibrate` keeps them; None for a card from before they were)."""

    def policy(self, member: int | None = None) -> AISPolicy:
        """The learnt policy (with `member`, that member of an ensemble alone)."""

        def make(n: int, seed: int, temporal: bool) -> Act:
            return self.make_act(n, seed, temporal, member)

        return AISPolicy(AISSpace.from_card(self.card, self.corridor), make)

    @abstractmethod
    def make_act(self, n: int, seed: int, temporal: bool, member: int | None = None) -> Act:
        """The policy for a batch of n rows (`aisdati.ais.policy.MakeAct`), of one member."""

    def score_tracks(
        self, tracks: Sequence[Track], how: ScoreSettings, also: Sequence[str]
    ) -> Scores:
        """Every score by the whole ensemble, but `stepspread` of a cross-fitted model (and
        `stepod`, which rests on it): member by member (`member_wise`), as its threshold was
        calibrated."""
        scores = self.score_with(self.policy(), tracks, how, also)
        wanted = {how.score, *also}
        if wanted & {"stepspread", "stepod"} and self.card.lane_config.crossfit:
            scores.parts |= self.member_wise(tracks, how, ("stepspread",))
            if "stepod" in wanted:
                scores.parts["stepod"] = self.stepod(scores.parts)
            if how.score in ("stepspread", "stepod"):
                scores.score_m = scores.parts[how.score]
        return scores

    def stepod(self, parts: dict[str, np.ndarray]) -> np.ndarray:
        """`stepod` of the scored `stepspread` and `od` (`aisdati.detectors.od.stepod_scores`)."""
        cal = self.calibration_of("stepspread"), self.calibration_of("od")
        return stepod_scores(parts["stepspread"], parts["od"], *cal)

    def member_wise(
        self, tracks: Sequence[Track], how: ScoreSettings, kinds: Sequence[str]
    ) -> dict[str, np.ndarray]:
        """[N] each of `kinds` of each track by each member alone (its K draws), the mean over
        the members. A cross-fitted calibration scores each training track with one member; the
        ensemble's K draws spread over members that disagree, so for `stepspread` (an error
        over the draws' spread) a track scored by the ensemble scored 5-11x lower than one
        member would score it, and the threshold flagged almost nothing forward in time
        (docs/results/forward.md)."""
        one = replace(how, score=kinds[0])
        members = range(self.card.lane_config.members)
        got = [self.score_with(self.policy(m), tracks, one, kinds[1:]).parts for m in members]
        return {k: np.mean([g[k] for g in got], axis=0) for k in kinds}

    def score_with(
        self, policy: AISPolicy, tracks: Sequence[Track], how: ScoreSettings, also: Sequence[str]
    ) -> Scores:
        """`score_tracks` with a given policy (one member of the ensemble, for calibration)."""
        positions = [t.positions for t in tracks]
        wanted = {how.score, *also}
        for name in wanted & RATIO_SCORES.keys():
            wanted |= set(RATIO_SCORES[name])
        if wanted & {"area", "od"}:
            wanted |= {"lane", "od"}
        if "stepod" in wanted:
            wanted |= {"stepspread"}
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
            bound = self.traffic_of(positions, len(traffic), how)
            profiles["lane"] = [
                lane_distances(p, [*e, *(traffic[j] for j in b)], how.lane_course_km * 1000.0)
                for p, e, b in zip(positions, every, bound, strict=True)
            ]
            parts["lane"] = np.array([tail_mean(d, how.tail) for d in profiles["lane"]])
        if wanted & set(STEP_SCORES):
            dts = [t.dts for t in tracks]
            draws = policy.step_draws(positions, dts, how.rollouts, how.seed)
            errors, predicted = best_draws(*draws)
            parts["step"] = np.array([tail_mean(e, how.tail) for e in errors])
            parts["steprate"] = np.array(
                [tail_mean(error_rates(e, d), how.tail) for e, d in zip(errors, dts, strict=True)]
            )
            parts["stepspread"] = np.array(
                [
                    tail_mean(error_surprises(e, q), how.tail)
                    for e, q in zip(errors, draws[1], strict=True)
                ]
            )
            profile = [np.concatenate([[0.0], e]) for e in errors]
            shown = [np.vstack([p[:1], q]) for p, q in zip(positions, predicted, strict=True)]
            for name in STEP_SCORES:
                profiles[name], evidence[name] = profile, shown
        if "traffic" in wanted:
            kept = self.kept_training_tracks()
            parts["traffic"], profiles["traffic"] = kept.lane_scores(positions, how)
        if wanted & {"od", "stepod"}:
            parts["od"] = self.od_scores(positions)
        if "od" in wanted:
            profiles["od"], evidence["od"] = profiles["lane"], evidence["lane"]
        if "stepod" in wanted:
            parts["stepod"] = self.stepod(parts)
            profiles["stepod"], evidence["stepod"] = profiles["step"], evidence["step"]
        if "area" in wanted:
            parts["area"] = area_scores(parts["lane"], parts["od"], self.calibration_of("od"))
            profiles["area"], evidence["area"] = profiles["lane"], evidence["lane"]
        for name in wanted & RATIO_SCORES.keys():
            medians_of = {k: self.calibration_of(k) for k in RATIO_SCORES[name]}
            parts[name] = ratio_sum(parts, medians_of, name)
            profiles[name] = profiles["step"]
            evidence[name] = evidence["rollout" if name == "both" else "step"]
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
        starts, goals = self.start_points, self.end_points
        steps = max(1, round(self.card.data.points / len(starts)) - 1)
        stream = int(np.random.SeedSequence([how.seed, 2]).generate_state(1)[0])
        horizons = np.full(len(starts), steps)
        paths = policy.generate(starts, horizons, 1, stream, how.lane_reach, goals)
        return list(paths)

    def traffic_of(
        self, positions: Sequence[np.ndarray], count: int, how: ScoreSettings
    ) -> list[np.ndarray]:
        """Per track, which of the `count` traffic rollouts join its lane: all of them, or for a
        goal-conditioned model those of training tracks bound the same way (module docstring)."""
        if not count or not self.card.lane_config.goal or self.end_points is None:
            return [np.arange(count)] * len(positions)
        starts = np.array([p[0] for p in positions])
        ends = np.array([p[-1] for p in positions])
        bound = od_pairs_m(starts, ends, self.start_points, self.end_points)
        return [np.nonzero(row <= how.near_km * 1000.0)[0] for row in bound]

    def kept_training_tracks(self) -> Traffic:
        """The training tracks; refused for a model from before policies kept them."""
        if self.training_tracks is None:
            raise UserError(
                f"model {self.name} does not keep its training tracks (trained before "
                "--score steptraffic existed): retrain it for that score"
            )
        return self.training_tracks

    def od_scores(self, positions: Sequence[np.ndarray]) -> np.ndarray:
        """Each track's origin-destination distance to the training tracks (`Detector.od_m`);
        refused for a card that does not record where its tracks end."""
        if self.end_points is None:
            raise UserError(
                f"model {self.name} does not record where its training tracks end (a card from "
                "before 0.2.0): retrain it for --score area"
            )
        return self.od_m(*track_ends(positions))

    def calibration_of(self, key: str) -> np.ndarray:
        values = self.card.calibration.get(key)
        if not values:
            raise UserError(f"model {self.name} has no {key} calibration scores: retrain it")
        return np.asarray(values, np.float64)

    def calibrate(
        self,
        tracks: Sequence[Track],
        how: ScoreSettings | None = None,
        folds: np.ndarray | None = None,
    ) -> None:
        """Score the training tracks every way; `threshold`, `both` and `area` read these.
        With `folds` (cross-fitting), the tracks of fold m are scored by member m alone, which
        did not train on them; without, by the whole model that did. The tracks are kept as
        the model's traffic, their traffic scores leave-one-vessel-out."""
        how = replace(how or self.how, score="rollout")
        kinds = ("rollout", *STEP_SCORES, "lane")
        if folds is None:
            parts = self.score_with(self.policy(), tracks, how, kinds[1:]).parts
        else:
            parts = {k: np.empty(len(tracks)) for k in kinds}
            for m in np.unique(folds):
                rows = np.nonzero(folds == m)[0]
                got = self.score_with(self.policy(int(m)), [tracks[i] for i in rows], how, kinds)
                for k in kinds:
                    parts[k][rows] = got.parts[k]
        cal = {k: [round(float(v), 4 if k in SCORE_UNITS else 2) for v in parts[k]] for k in kinds}
        self.training_tracks = Traffic.of(tracks, self.card.cluster)
        cal["traffic"] = [round(float(v), 2) for v in self.training_tracks.calibration(how)]
        for name in RATIO_SCORES:
            cal[name] = [round(float(v), 4) for v in ratio_sum(cal, cal, name)]
        if self.end_points is not None:
            ends = np.array([t.positions[-1] for t in tracks])
            starts = np.array([t.positions[0] for t in tracks])
            od = od_distances(starts, ends, starts, ends, leave_one_out=True)
            area = area_scores(cal["lane"], od, od)
            cal["od"] = [round(float(v), 2) for v in od]
            cal["area"] = [round(float(v), 2) for v in area]
            own = cal["stepspread"], cal["od"]  # as scoring reads them back from the card
            stepod = stepod_scores(*own, *own)
            cal["stepod"] = [round(float(v), 4) for v in stepod]
        self.card.calibration = cal
        self.card.calibrated_with = how.calibrated_with()


def saved_traffic(stem: Path, card: ModelCard) -> Traffic | None:
    """The training tracks saved beside a model calibrated with them (`<stem>.npz`)."""
    if "traffic" not in card.calibration:
        return None
    return Traffic.read(stem.with_suffix(".npz"), card)


def save_traffic(stem: Path, traffic: Traffic | None) -> None:
    if traffic is not None:
        atomic_write_bytes(stem.with_suffix(".npz"), traffic.to_bytes())


def saved_corridor(stem: Path, card: ModelCard) -> Corridor | None:
    """The corridor saved beside a model trained with `region="corridor"`."""
    if card.lane_config.region != "corridor":
        return None
    return Corridor.from_file(stem.with_suffix(".corridor.npz"))
