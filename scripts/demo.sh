#!/usr/bin/env bash
# The one-command AIS demo: ingest -> train -> detect on a real week of New York Harbor traffic that
# ships with the project (tests/data, see tests/data/PROVENANCE.md), in a few minutes on 2 CPU cores.
#
#   scripts/demo.sh            # outputs under runs/demo (OUT=dir to change)
#
# The sample holds positions only (no reported SOG/COG): ingest derives them, and in a harbour
# they wiggle, so every track lands in the `other` cluster; the demo therefore learns `other`
# traffic from a random 20 of its 275 tracks (20 short episodes instead of the paper's 170) and
# judges the remaining tracks that start within 10 km of a training start. With so short a
# training budget the model is crude: the scores rank tracks by how far they go from what it has
# learnt, which shows the whole pipeline working, not the paper's detection quality.
set -euo pipefail
cd "$(dirname "$0")/.."

OUT=${OUT:-runs/demo}
EPISODES=${EPISODES:-20}
TRACKS=${TRACKS:-20}
SAMPLE=tests/data/NYHarbor_2020_12_first_week_points.csv.gz

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

echo "== 2/3 train: cluster other, $TRACKS tracks, $EPISODES episodes"
"$AISDATI" train --cluster other --data "$OUT/processed" --out "$OUT/models" \
  --max-tracks "$TRACKS" --episodes "$EPISODES" --patience 0 --seed 0

echo "== 3/3 detect: K = 10 rollouts per test track, threshold 0.75"
"$AISDATI" detect --data "$OUT/processed" --models "$OUT/models" --out "$OUT/report" \
  --rollouts 10 --threshold 0.75

echo "== done in $(( $(date +%s) - start )) s: map $OUT/report/map.png (zoomable: $OUT/report/map.html)"
