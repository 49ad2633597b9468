#!/usr/bin/env bash
# The one-command AIS demo: an analyst's month, on two months of real traffic around Kitimat, BC,
# that ship with the project (tests/data, see tests/data/PROVENANCE.md), in about a minute on
# 2 CPU cores:
#
#   1. ingest: clean, segment and cluster the reports of July and August 2018;
#   2. evaluate --before: train one model of the whole area (the area's default: behaviour
#      cloning cross-fitted over three vessel folds, which judges each report by its one-step
#      prediction error over the spread of its own draws, and the nearest-track baseline) on
#      July, write detours, position jumps and loitering circles into 30 % of the August tracks,
#      and judge every August track;
#   3. detect: judge August with the July model, flag what scores above the threshold calibrated
#      on July tracks the model did not fit (the default, 5 %) and every track with reports
#      well inland, check the flags against the injected labels and draw the map.
#
#   scripts/demo.sh            # outputs under runs/demo (OUT=dir, EPISODES=n: the training
#                              # tracks BC learns from per member, 170 by default)
set -euo pipefail
cd "$(dirname "$0")/.."

OUT=${OUT:-runs/demo}
EPISODES=${EPISODES:-170}
BEFORE=2018-08-01
SAMPLE=tests/data/AIS_2018_07-08_Kitimat.csv.gz

if [ -x .venv/bin/aisdati ]; then
  AISDATI=.venv/bin/aisdati
elif command -v aisdati >/dev/null 2>&1; then
  AISDATI=aisdati
else
  echo "== setting up .venv (CPU torch + aisdati)"
  make setup
  AISDATI=.venv/bin/aisdati
fi

start=$(date +%s)
echo "== 1/3 ingest: $SAMPLE"
"$AISDATI" ingest --input "$SAMPLE" --roi none --min-points 100 --out "$OUT/processed"

echo "== 2/3 evaluate: train on July, judge every August track (30 % altered)"
"$AISDATI" evaluate --data "$OUT/processed" --cluster all --before "$BEFORE" \
  --altered 0.3 --detectors bc,nearest --kinds detour,jump,loiter --episodes "$EPISODES" \
  --out "$OUT/evaluate"

echo "== 3/3 detect: every August track, judged by the July model of the area"
"$AISDATI" detect --data "$OUT/evaluate/data" --models "$OUT/evaluate/models" --cluster all \
  --labels "$OUT/evaluate/data/labels.csv" --out "$OUT/report"

echo "== done in $(( $(date +%s) - start )) s"
echo "   routes:     $OUT/processed/routes.png"
echo "   evaluation: $OUT/evaluate/evaluation.json, roc_pr.png, examples.png"
echo "   detection:  $OUT/report/map.png (zoomable: map.html), evidence/, scores.parquet"
echo "== what it found"
python3 - "$OUT" <<'PY'
import json, sys
from pathlib import Path

out = Path(sys.argv[1])
rep = json.loads((out / "report/report.json").read_text())
cov = rep["coverage"]
m = json.loads((out / "report/metrics.json").read_text())
found = round(m["recall"] * m["anomalies_labelled"])
normal = m["labelled_tracks"] - m["anomalies_labelled"]
auc = "n/a" if m["roc_auc"] is None else f"{m['roc_auc']:.3f}"
skipped = ", ".join(f"{v} ({k})" for k, v in cov["not_judged"].items())
judged = (f"all {cov['judged']}" if cov["judged"] == cov["candidates"]
          else f"{cov['judged']} of {cov['candidates']}")
print(f"   coverage: {judged} August tracks judged{'; not judged: ' + skipped if skipped else ''}"
      f" ({cov['training_tracks']} July training tracks left out)")
print(f"   August: {m['labelled_tracks']} tracks, {m['anomalies_labelled']} altered; ROC AUC {auc}")
print(f"   at the calibrated threshold: {m['false_alarm_rate']:.0%} of the {normal} normal tracks "
      f"flagged, {found} of {m['anomalies_labelled']} anomalies (recall {m['recall']:.2f}); "
      f"{rep['flagged_ashore']} of the flags for reports ashore (--no-ashore: the model alone)")
kinds = ", ".join(f"{n} {k}" for k, n in rep["events_by_kind"].items()) or "none"
print(f"   events: {len(rep['events'])} over {rep['reports_judged']:,} reports judged ({kinds});"
      " on map.html's events layer, in events.parquet / events.geojson")
for e in rep["events"][:12]:
    print(f"     {e['start'][:16]}  {e['kind']:<20} MMSI {e['mmsi']}  track {e['track_id']}"
          f"  at {e['lat']:.4f}, {e['lon']:.4f}  x{e['strength']:.2f}  {e['evidence']}")
if len(rep["events"]) > 12:
    print(f"     ... and {len(rep['events']) - 12} more in report.json")
PY
