#!/usr/bin/env bash
# The one-command AIS demo, on two months of real traffic around Kitimat, BC, that ship with the
# project (tests/data, see tests/data/PROVENANCE.md), in about 5 minutes on 2 CPU cores:
#
#   1. ingest: clean, segment and cluster the reports into routes (lanes, one per direction);
#   2. evaluate: split the north-west -> south-east lane's tracks by vessel, write detours,
#      position jumps and loitering circles into half of the held-out tracks, train DATI (and the
#      nearest-track baseline) on the rest and measure how well each ranks the altered tracks;
#   3. detect: judge the held-out tracks with the trained DATI model, flag what scores above its
#      threshold calibrated on its own training tracks (--contamination 0.05), check
#      the flags against the injected labels and draw the map.
#
#   scripts/demo.sh            # outputs under runs/demo (OUT=dir, EPISODES=n to change)
set -euo pipefail
cd "$(dirname "$0")/.."

OUT=${OUT:-runs/demo}
EPISODES=${EPISODES:-30}
ROUTE=${ROUTE:-route-2}
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

echo "== 2/3 evaluate: $ROUTE, DATI ($EPISODES episodes) against the nearest-track baseline"
"$AISDATI" evaluate --data "$OUT/processed" --cluster "$ROUTE" --detectors dati,nearest \
  --kinds detour,jump,loiter --episodes "$EPISODES" --out "$OUT/evaluate"

echo "== 3/3 detect: the held-out tracks of $ROUTE, judged by DATI"
"$AISDATI" detect --data "$OUT/evaluate/data" --models "$OUT/evaluate/models" \
  --cluster "$ROUTE" --labels "$OUT/evaluate/data/labels.csv" --contamination 0.05 \
  --out "$OUT/report"

echo "== done in $(( $(date +%s) - start )) s"
echo "   routes:     $OUT/processed/routes.png"
echo "   evaluation: $OUT/evaluate/evaluation.json, roc_pr.png, examples.png"
echo "   detection:  $OUT/report/map.png (zoomable: map.html), evidence/, scores.parquet"
echo "== what it found"
python3 - "$OUT" <<'PY'
import json, sys
from pathlib import Path

out = Path(sys.argv[1])
fidelity = json.loads((out / "evaluate/evaluation.json").read_text())["lane_fidelity_m"]
m = json.loads((out / "report/metrics.json").read_text())
found = round(m["recall"] * m["anomalies_labelled"])
print(f"   DATI's rollouts: {fidelity['dati'] / 1000:.2f} km from the held-out normal tracks "
      f"(median, best of 10; nearest training track: {fidelity['nearest'] / 1000:.2f} km)")
print(f"   flagged {m['flagged']} of {m['labelled_tracks']} held-out tracks: {found} of the "
      f"{m['anomalies_labelled']} injected anomalies (precision {m['precision']:.2f}, recall "
      f"{m['recall']:.2f}), ROC AUC {m['roc_auc']:.3f}")
PY
