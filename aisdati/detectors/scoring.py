"""What scoring tracks is asked for (`ScoreSettings`) and what it returns (`Scores`), for every
detector: a score per track in metres (higher = more abnormal), where along the track it strays,
and what it was compared with."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aisdati.ais.card import CalibratedWith
from aisdati.geo import draw_spread

SCORE_CHUNK = 64
"""Tracks one scoring task holds (`Detector.score`): chunks of the test set, in its order, so
the scores are the same whatever runs the tasks. Each chunk regenerates the lane traffic (one
rollout per training track, at most 170), which 64 tracks of 30 lane rollouts each outweigh
more than 10 times; smaller chunks would spread a few hundred tracks wider over workers."""


POSITION_ACCURACY_M = 10.0
"""`error_surprises`: added to the draws' spread, an AIS position's accuracy, so that a report
the draws agree on to a metre is not judged against a metre."""


def error_surprises(errors_m: np.ndarray, draws: np.ndarray) -> np.ndarray:
    """A track's best-of-K one-step errors (metres [n - 1]) each over the spread of its K draws
    ([n - 1, K, 2] lon/lat; `aisdati.geo.draw_spread`) plus `POSITION_ACCURACY_M`: how far the
    report lies from where the model expected it, in units of how sure the model was. Where the
    members disagree or a fast vessel's next report fans out, an error of a few hundred metres
    is no surprise; where they agree it is. `stepspread`; measured forward in time in
    docs/results/forward.md."""
    return errors_m / (draw_spread(draws)[1] + POSITION_ACCURACY_M)


def score_chunks(count: int) -> list[range]:
    """The tracks (by index) of each scoring task: consecutive chunks of `SCORE_CHUNK`, and
    one empty chunk for no track (a detector still says what an empty set scores)."""
    return [range(i, min(i + SCORE_CHUNK, count)) for i in range(0, max(count, 1), SCORE_CHUNK)]


def tail_mean(values: np.ndarray, fraction: float) -> float:
    """Mean of the largest `fraction` of the values (at least one): a short stretch far off
    counts as much in a long track as in a short one."""
    k = max(1, math.ceil(len(values) * fraction))
    return float(np.partition(values, len(values) - k)[-k:].mean())


@dataclass(frozen=True, kw_only=True)
class ScoreSettings:
    score: str = "lane"
    """lane, rollout (the paper's), step (teacher-forced) or stepspread (the same errors over
    the draws' spread); see `aisdati.ais.policy`."""
    rollouts: int = 10
    """K: free rollouts per track (the rollout score is the best of K), and one-step draws
    per report."""
    lane_rollouts: int = 30
    """Lane score: free rollouts per track that make up its lane (the K of the rollout score
    and L - K more). A lane is where the policy goes, estimated from samples: on the Kitimat
    routes over three seeds and several noise draws, DATI's pooled lane AUC (by position only)
    averaged 0.879 with 10, 0.892 with 30 and 0.904 with 100 rollouts (docs/results/levers.md);
    with the course weighed, 100 add little. 30 keeps scoring and calibration affordable."""
    lane_reach: float = 2.0
    """Lane score: the rollouts run this many times the track's number of steps (the rollout
    score always uses the track's own number). DATI's rollouts on Kitimat ran at half to twice
    the real pace (SOG x dt), so over the track's number of steps a slow one stopped half-way
    and every later report was "far from the lane"; twice as many steps cover a model at half
    pace, and a fast one just goes on along the corridor."""
    lane_course_km: float = 2.0
    """Lane score: what sailing against the lane's course costs, km (across it: 0.7 x as
    much); 0 judges position only. See `aisdati.geo.lane_distances`. 2 km gave DATI the best
    pooled lane AUC averaged over two areas (Kitimat's fjord lanes, where 4 km was better, and
    NY Harbor's ferry crossings, where 4 km was worse than none; docs/results/areas.md)."""
    lane_traffic: bool = True
    """Lane score of a learnt policy: each track's lane also holds one rollout from every
    training track's start (`PolicyDetector.traffic`), so the lane is where the model's
    traffic goes, not only where it goes from this track's start. A real track that starts
    off the lane and joins it was judged only against rollouts that never reached the lane
    it joined. With it DATI's pooled lane AUC rose 0.942 -> 0.966 on Kitimat and 0.945 ->
    0.959 on NY Harbor (docs/results/areas.md)."""
    tail: float = 0.1
    """Step and lane scores: the mean of the largest `tail` of a track's per-report distances.
    Measured at 0.05-1 on both areas (the one-off `benchmarks/lane_score.py --tail`, in git
    history at de1e87e): 0.1 gave DATI the best pooled lane AUC averaged over Kitimat and NY
    Harbor (0.15 was level; larger fractions dilute a short jump or loiter on the ferry routes,
    smaller ones let a few stray reports decide); docs/results/areas.md."""
    reported_motion: bool = False
    """Step scores: each draw judged by the larger of its distances to the next position and
    to where the report's own SOG and COG put the vessel (`aisdati.ais.policy.reported_next`),
    not by the first alone. A model's calibration decides it (`calibrated_with`): the area
    preset's BC reads the reported motion (`aisdati.ais.space.reads_reported_motion`; on
    Kitimat +0.070 ROC AUC over shifts, course and speed noise, docs/results/
    reported-motion.md)."""
    near_km: float = 10.0
    """`nearest`: compare with training tracks that start within this distance."""
    seed: int = 0

    def calibrated_with(self) -> CalibratedWith:
        """What a card records of the settings its calibration scores were computed with:
        `Detector.threshold` refuses to flag with others."""
        return CalibratedWith(
            lane_course_km=self.lane_course_km,
            lane_traffic=self.lane_traffic,
            rollouts=self.rollouts,
            lane_rollouts=self.lane_rollouts,
            reported_motion=self.reported_motion,
        )


@dataclass
class Scores:
    """What a detector says about N tracks."""

    score: np.ndarray
    """[N] the scores, in their kind's unit (`aisdati.scores.Score.unit`); higher = more
    abnormal."""
    profiles: list[np.ndarray]
    """Per track, the local deviation (m) at each of its points: where it strays."""
    evidence: list[np.ndarray]
    """Per track, what it was compared with ([m, 2] lon/lat): best rollout, nearest training
    track, or the one-step predictions."""
    parts: dict[str, np.ndarray] = field(default_factory=dict)
    """Every score computed in the pass, by kind ([N] each, `score`'s among them)."""


def joined(chunks: list[Scores]) -> Scores:
    """The scores of consecutive chunks of tracks as one."""
    return Scores(
        np.concatenate([c.score for c in chunks]),
        [p for c in chunks for p in c.profiles],
        [e for c in chunks for e in c.evidence],
        {k: np.concatenate([c.parts[k] for c in chunks]) for k in chunks[0].parts},
    )
