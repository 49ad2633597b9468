"""The mixture of route models and an area model, forward in time (issue 26; not a test).

Takes a finished `aisdati evaluate --cluster all --split time --before DATE` run (its data/
holds the training period and the judged period with anomalies written in, labels.csv, and its
models/ the area model `all`), trains one DATI model per route on the training period's tracks
(`aisdati train --cluster routes`), puts the area model beside them and judges every later
track with `aisdati detect --cluster all`: a track goes to the route model whose training tracks
start and end where it does, else to the area model. Scores of different models are put on one
scale by dividing each by its judging model's calibrated threshold (--contamination 0.05), as
`evaluate --cluster routes` pools routes. Prints coverage, ROC AUC, average precision, the share
of normal tracks and of anomalies flagged, AUC per kind, and the routes' training time.

Run: python benchmarks/forward_mixture.py RUN --before DATE [--episodes 30] [--score lane]
     [--method nearest]   # the same mixture of nearest-track models (the baseline)
     [--area-models DIR]  # a run made with `evaluate --models DIR` (e.g. --strength 0.3)
     [--no-ashore]        # the models' scores alone (`aisdati.tracks.ashore`)
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from aisdati.detection.run import DetectSettings, detect
from aisdati.evaluation.metrics import flagging, ranking
from aisdati.tracks.ashore import AshoreCheck


def training_period(data: Path, out: Path, before: pd.Timestamp) -> None:
    """The tracks of `data` that start before `before`, in ingest's schema, in `out`."""
    out.mkdir(parents=True, exist_ok=True)
    tracks = pq.read_table(data / "tracks.parquet")
    cut = pa.scalar(before.to_pydatetime(), tracks.schema.field("start").type)
    tracks = tracks.filter(pc.less(tracks["start"], cut))
    points = pq.read_table(data / "points.parquet")
    points = points.filter(pc.is_in(points["track_id"], tracks["track_id"]))
    pq.write_table(tracks, out / "tracks.parquet")
    pq.write_table(points, out / "points.parquet")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="an `aisdati evaluate --split time` output folder")
    ap.add_argument("--before", required=True, help="its --before date")
    ap.add_argument("--episodes", type=int, default=30)
    ap.add_argument("--score", default="lane")
    ap.add_argument("--method", default="dati", choices=("dati", "nearest"))
    ap.add_argument("--area-models", type=Path, help="where the area model is (default RUN/models)")
    ap.add_argument("--no-ashore", dest="ashore", action="store_false", help="no ashore rule")
    args = ap.parse_args()
    before = pd.Timestamp(args.before, tz="UTC")
    past = args.run / "mixture" / "past"
    models = args.run / "mixture" / ("models" if args.method == "dati" else "nearest-models")
    area = "all" if args.method == "dati" else "all-nearest"
    training_period(args.run / "data", past, before)
    t0 = time.perf_counter()
    if not any(models.glob("route-*.json")):
        cmd = [sys.executable, "-m", "aisdati.cli", "train", "--cluster", "routes", "--data",
               str(past), "--out", str(models), "--episodes", str(args.episodes),
               "--method", args.method, "-q"]  # fmt: skip
        subprocess.run(cmd, check=True)
    train_s = time.perf_counter() - t0
    for f in (args.area_models or args.run / "models").glob(f"{area}.*"):
        shutil.copy2(f, models / f.name)
    settings = DetectSettings(
        data_dir=args.run / "data", models_dir=models, out_dir=args.run / "mixture" / "report",
        cluster="all", contamination=0.05, score=args.score, method=args.method,
        ashore=args.ashore,
    )  # fmt: skip
    result = detect(settings)
    sc = result.scores
    cut = {m.name: m.threshold(settings.how, 0.05) for m in result.models}
    ratio = sc["score_m"] / sc["model"].map(cut)
    sc["ratio"] = AshoreCheck().ranked(ratio, sc["ashore_reports"], sc["n_points"])
    labels = pd.read_csv(args.run / "data" / "labels.csv").set_index("track_id")
    sc = sc[sc["track_id"].isin(labels.index)]
    y = labels.loc[sc["track_id"], "label"].to_numpy()
    kind = labels.loc[sc["track_id"], "kind"].fillna("").to_numpy()
    flags = flagging(y, sc["flagged"].to_numpy())
    rank = ranking(y, sc["ratio"].to_numpy())
    print(f"judged {len(sc)} of {len(labels)} later tracks: {result.coverage.judged_by}")
    print("| ROC AUC | avg precision | normal flagged | anomalies flagged | "
          "AUC detour | AUC jump | AUC loiter | routes' training s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    per_kind = []
    for k in ("detour", "jump", "loiter"):
        keep = (kind == k) | (y == 0)
        per_kind.append(ranking(y[keep], sc["ratio"].to_numpy()[keep])["roc_auc"])
    cells = [rank["roc_auc"], rank["average_precision"], flags["false_alarm_rate"],
             flags["recall"], *per_kind]  # fmt: skip
    shown = ["n/a" if c is None else f"{c:.3f}" for c in cells]  # a kind with no anomaly
    print("| " + " | ".join(shown) + f" | {train_s:.0f} |")


if __name__ == "__main__":
    main()
