"""`--score steptraffic` measured on forward grids trained before the score existed (not a test).

steptraffic = step / median(training step scores) + traffic / median(training traffic scores),
where traffic is the distance to the training tracks themselves: for a model of an area, exactly
`nearest`'s lane score over the area, and its training scores nearest's leave-one-vessel-out
calibration (`aisdati.detectors.traffic`; tests/test_area.py checks that a model's own
steptraffic is this sum). So each cell of `benchmarks/detection_quality.py --forward
--detectors dati,nearest` holds every term already: DATI's step scores and cross-fitted
calibration, nearest's lane scores and calibration. This script sums them per cell, ranks the
tracks the ashore rule flagged first (as the evaluation does), and prints per grid the nine-cell
mean ROC AUC of step, nearest's lane and steptraffic, and at `--contamination 0.05` (the 0.95
quantile of the training tracks' own sums) the share of normal and of altered tracks flagged.
"either" flags a track when either term alone passes its own 5 % threshold: the most that a rule
of these two calibrated terms can flag; a second table gives each kind's share.

`--traffic-calibration track` recomputes the traffic term's calibration leave-one-track-out
(each training track against every other, its own vessel's other trips included) from the
nearest model's kept training tracks, instead of the models' leave-one-vessel-out; nearest's
lane is then thresholded on it too.

Run: python benchmarks/step_traffic.py runs/grid/kitimat/forward-s1-at-sea [more grid folders]
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from aisdati.ais.card import read_card
from aisdati.detectors.scoring import ScoreSettings, ratio_sum
from aisdati.detectors.traffic import Traffic
from aisdati.tracks.ashore import AshoreCheck

RULE = AshoreCheck()
CONTAMINATION = 0.05
KINDS = ("detour", "jump", "loiter")


TIE_BREAK = 1e-6
"""The rank sum's tie-break: tracks beyond every training score of both terms rank by the
median-ratio sum."""


def ranks(values: np.ndarray, calibration: np.ndarray) -> np.ndarray:
    """Each value's share of the training tracks' own scores at or below it (0-1)."""
    cal = np.sort(calibration)
    return np.searchsorted(cal, np.asarray(values, np.float64), side="right") / len(cal)


def calibration(card: Path, key: str) -> np.ndarray:
    return np.asarray(json.loads(card.read_text())["calibration"][key], np.float64)


def leave_one_track_out(models: Path, cache: dict[Path, np.ndarray]) -> np.ndarray:
    """The training tracks' traffic scores, each against all the other training tracks."""
    stem = (models / "all-nearest").resolve()
    if stem not in cache:
        kept = Traffic.read(stem.with_suffix(".npz"), read_card(stem.with_suffix(".json")))
        each_its_own = Traffic(kept.tracks, np.arange(len(kept.tracks)), kept.whole_area)
        cache[stem] = each_its_own.calibration(ScoreSettings())
    return cache[stem]


def judged(cell: Path) -> tuple[pd.DataFrame, pd.DataFrame, Path]:
    """One evaluate folder's rows of DATI's step score and of nearest's lane score (by track,
    the same order), and the folder of the models that judged them."""
    scores = pd.read_parquet(cell / "scores.parquet")
    models = json.loads((cell / "evaluation.json").read_text())["settings"]["models_dir"]
    pick = lambda det, kind: scores[(scores.detector == det) & (scores.score == kind)]  # noqa: E731
    step = pick("dati", "step").set_index("track_id")
    lane = pick("nearest", "lane").set_index("track_id").loc[step.index]
    return step, lane, Path(models) if models else cell / "models"


def cells_of(grid: Path) -> list[Path]:
    """A grid folder's evaluated cells (`train*-seed*`)."""
    cells = sorted(p for p in grid.glob("train*-seed*") if (p / "scores.parquet").is_file())
    if not cells:
        raise SystemExit(f"{grid}: no evaluated cells")
    return cells


def print_grids(
    grids: list[Path],
    result: Callable[[Path], dict[str, float]],
    figures: dict[str, tuple[str, str]],
    rated: tuple[str, ...],
    kinds: tuple[str, ...],
) -> None:
    """One markdown row per grid of its cells' means: `figures` (header -> (key, format)), then
    FA / recall of each rule in `rated`; then each kind's share flagged by the rules `kinds`."""
    headers = [*figures, *(f"{k} FA / recall" for k in rated)]
    print("| grid | cells | " + " | ".join(headers) + " |\n|---|---|" + "---|" * len(headers))
    means = {}
    for grid in grids:
        cells = cells_of(grid)
        mean = means[grid] = pd.DataFrame([result(c) for c in cells]).mean()
        shown = [format(mean[key], style) for key, style in figures.values()]
        shown += [f"{mean[k + ' FA']:.3f} / {mean[k + ' recall']:.2f}" for k in rated]
        print(f"| {grid} | {len(cells)} | " + " | ".join(shown) + " |")
    print(f"\nShare of each kind flagged (ashore rule included): {' / '.join(kinds)}")
    print("\n| grid | " + " | ".join(KINDS) + " |\n|---|" + "---|" * len(KINDS))
    for grid, mean in means.items():
        shares = [" / ".join(f"{mean[f'{k} {kind}']:.2f}" for k in kinds) for kind in KINDS]
        print(f"| {grid} | " + " | ".join(shares) + " |")


def flag_rates(flags: dict[str, np.ndarray], label: np.ndarray, kinds: np.ndarray) -> dict:
    """FA and recall of each rule's flags, and the share of each kind it flags."""
    out = {}
    for k, flagged in flags.items():
        out[f"{k} FA"], out[f"{k} recall"] = flagged[label == 0].mean(), flagged[label == 1].mean()
        for kind in KINDS:
            out[f"{k} {kind}"] = flagged[kinds == kind].mean() if (kinds == kind).any() else np.nan
    return out


def cell_result(cell: Path, by_track: dict[Path, np.ndarray] | None) -> dict[str, float]:
    """ROC AUC of each score, and (FA, recall) of step and steptraffic, on one evaluate folder."""
    step, lane, models = judged(cell)
    cal_step = calibration(models / "all.json", "step")
    cal_lane = calibration(models / "all-nearest.json", "lane")
    if by_track is not None:
        cal_lane = leave_one_track_out(models, by_track)
    if len(cal_step) != len(cal_lane):
        raise SystemExit(f"{cell}: the two models were calibrated on different tracks")
    medians = {"step": cal_step, "traffic": cal_lane}
    parts = {"step": step.value.to_numpy(), "traffic": lane.value.to_numpy()}
    ratio = ratio_sum(parts, medians, "steptraffic")  # what the score computes
    cal_ratio = ratio_sum(medians, medians, "steptraffic")
    values = {
        "step": step.value.to_numpy(),
        "lane": lane.value.to_numpy(),
        "steptraffic": ratio,
        "ranks": ranks(step.value, cal_step) + ranks(lane.value, cal_lane) + TIE_BREAK * ratio,
    }
    cal_ranks = ranks(cal_step, cal_step) + ranks(cal_lane, cal_lane) + TIE_BREAK * cal_ratio
    thresholds = {
        "step": np.quantile(cal_step, 1 - CONTAMINATION),
        "lane": np.quantile(cal_lane, 1 - CONTAMINATION),
        "steptraffic": np.quantile(cal_ratio, 1 - CONTAMINATION),
        "ranks": np.quantile(cal_ranks, 1 - CONTAMINATION),
    }
    counts, lengths = step.ashore_reports.to_numpy(), step.n_points.to_numpy()
    label = step.label.to_numpy()
    out = {k: roc_auc_score(label, RULE.ranked(v, counts, lengths)) for k, v in values.items()}
    flags = {k: (values[k] > threshold) | RULE.flags(counts) for k, threshold in thresholds.items()}
    flags["either"] = flags["step"] | flags["lane"]
    return out | flag_rates(flags, label, step.kind.to_numpy())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("grids", type=Path, nargs="+", help="grid folders (<out>/<area>/<tier>)")
    parser.add_argument(
        "--traffic-calibration",
        choices=("vessel", "track"),
        default="vessel",
        help="leave one vessel out (the models') or one track out (recomputed)",
    )
    args = parser.parse_args()
    by_track: dict[Path, np.ndarray] | None = {} if args.traffic_calibration == "track" else None
    figures = {
        "step": ("step", ".3f"),
        "nearest lane": ("lane", ".3f"),
        "steptraffic": ("steptraffic", ".3f"),
        "ranks": ("ranks", ".3f"),
    }
    print_grids(
        args.grids,
        lambda cell: cell_result(cell, by_track),
        figures,
        ("step", "lane", "steptraffic", "ranks", "either"),
        ("step", "lane", "either"),
    )


if __name__ == "__main__":
    main()
