"""What the detectors that judge tracks with a learnt policy share: `dati` (the paper's) and `bc`.

Both score the same ways (`aisdati.ais.policy`): free rollouts (`rollout`, the paper's),
teacher-forced one-step errors (`step`, metres; `stepspread`, each over the spread of the
model's own draws) or the distance to the lane of the K rollouts (`lane`).
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from aisdati.ais.card import ModelCard
from aisdati.ais.corridor import Corridor
from aisdati.ais.policy import Act, AISPolicy, Draws, reported_next, track_keys
from aisdati.ais.space import reads_reported_motion
from aisdati.detectors.base import Detector
from aisdati.detectors.scoring import Scores, ScoreSettings, error_surprises, tail_mean
from aisdati.dtw import matched_distances
from aisdati.geo import haversine_m, lane_distances
from aisdati.scores import SCORES, scores_from
from aisdati.tracks.store import Track


class PolicyDetector(Detector):
    """A detector built on an `AISPolicy`; subclasses say how the policy acts."""

    lane_settings = ("lane_course_km", "lane_traffic")

    def policy(self, member: int | None = None) -> AISPolicy:
        """The learnt policy (with `member`, that member of an ensemble alone)."""

        def make(rows: Draws, temporal: bool) -> Act:
            return self.make_act(rows, temporal, member)

        return AISPolicy(self.card.space(self.corridor), make)

    @abstractmethod
    def make_act(self, rows: Draws, temporal: bool, member: int | None = None) -> Act:
        """The policy for a batch of n rows (`aisdati.ais.policy.MakeAct`), of one member."""

    def score_tracks(
        self, tracks: Sequence[Track], how: ScoreSettings, also: Sequence[str]
    ) -> Scores:
        """Every score by the whole ensemble, but the `member_wise` scores of a cross-fitted
        model (`aisdati.scores.Score`) member by member, as their threshold was calibrated."""
        scores = self.score_with(self.policy(), tracks, how, also)
        wise = tuple(k for k in dict.fromkeys((how.score, *also)) if SCORES[k].member_wise)
        if wise and self.card.lane_config.crossfit:
            scores.parts |= self.member_wise(tracks, how, wise)
            scores.score = scores.parts[how.score]
        return scores

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
        parts: dict[str, np.ndarray] = {}
        profiles: dict[str, list[np.ndarray]] = {}
        evidence: dict[str, list[np.ndarray]] = {}
        if wanted & set(scores_from("rollouts")):
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
        if wanted & set(scores_from("steps")):
            errors, draws = policy.step_draws(
                positions, [t.dts for t in tracks], how.rollouts, how.seed
            )
            best = [
                judged_steps(e, q, reported_target(t, how))
                for e, q, t in zip(errors, draws, tracks, strict=True)
            ]
            parts["step"] = np.array([tail_mean(e, how.tail) for e, _ in best])
            parts["stepspread"] = np.array(
                [
                    tail_mean(error_surprises(e, q), how.tail)
                    for (e, _), q in zip(best, draws, strict=True)
                ]
            )
            profile = [np.concatenate([[0.0], e]) for e, _ in best]
            shown = [np.vstack([p[:1], q]) for p, (_, q) in zip(positions, best, strict=True)]
            for name in scores_from("steps"):
                profiles[name], evidence[name] = profile, shown
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
        starts = self.card.data.starts
        steps = max(1, round(self.card.data.points / len(starts)) - 1)
        keys = track_keys(list(starts[:, None]), how.seed, stream=2)
        horizons = np.full(len(starts), steps)
        return list(policy.generate(starts, horizons, keys, range(1), how.lane_reach))

    def calibrate(
        self,
        tracks: Sequence[Track],
        how: ScoreSettings | None = None,
        folds: np.ndarray | None = None,
    ) -> None:
        """Score the training tracks every way; `threshold` reads these. With `folds`
        (cross-fitting), the tracks of fold m are scored by member m alone, which did not train
        on them; without, by the whole model that did."""
        reads = reads_reported_motion(self.card.preset, self.method)
        how = replace(how or self.how, score="rollout", reported_motion=reads)
        self.how = replace(self.how, reported_motion=reads)  # judges as it is calibrated
        kinds = tuple(SCORES)
        if folds is None:
            parts = self.score_with(self.policy(), tracks, how, kinds[1:]).parts
        else:
            parts = {k: np.empty(len(tracks)) for k in kinds}
            for m in np.unique(folds):
                rows = np.nonzero(folds == m)[0]
                got = self.score_with(self.policy(int(m)), [tracks[i] for i in rows], how, kinds)
                for k in kinds:
                    parts[k][rows] = got.parts[k]
        cal = {k: [round(float(v), SCORES[k].digits) for v in parts[k]] for k in kinds}
        self.card.calibration = cal
        self.card.calibrated_with = how.calibrated_with()


def reported_target(track: Track, how: ScoreSettings) -> np.ndarray | None:
    """Where the track's reported motion puts each next report (`reported_next`), when the
    step scores read it and the track has it."""
    if not how.reported_motion or track.sog is None or track.cog is None:
        return None
    return reported_next(track.positions, track.dts, track.sog, track.cog)


def judged_steps(
    errors: np.ndarray, draws: np.ndarray, target: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Of a track's K one-step draws at each report ([n - 1, K] errors in metres, [n - 1, K, 2]
    positions), the best draw's error and position: the draw nearest the next report, or with
    a `target` (`reported_target`) the draw whose larger distance to the two is smallest, so a
    report is as surprising as the farther of where the vessel went and where it said it goes
    (a report without SOG or COG: its position alone)."""
    if target is not None:
        with np.errstate(invalid="ignore"):
            said = haversine_m(draws[..., 0], draws[..., 1], target[:, None, 0], target[:, None, 1])
        errors = np.fmax(errors, said)
    rows = np.arange(len(errors))
    best = errors.argmin(axis=1)
    return errors[rows, best], draws[rows, best]


def saved_corridor(stem: Path, card: ModelCard) -> Corridor | None:
    """The corridor saved beside a model trained with `region="corridor"`."""
    if card.lane_config.region != "corridor":
        return None
    return Corridor.from_file(stem.with_suffix(".corridor.npz"))
