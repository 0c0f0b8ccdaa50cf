#!/usr/bin/env bash
# Re-measure detectors of the shipped COCO tables with this version's code, one store per run,
# and merge them into reports/coco and the shipped prediction tables, keeping the detectors not
# re-measured as they were (fidelity tables --earlier). Resumable: rerun the same line.
#   benchmarks/tools/resweep_model.sh STORE MODEL.onnx[@N] [MODEL.onnx[@N] ...]
# e.g. PROCESSES=2 benchmarks/tools/resweep_model.sh ~/.cache/fidelity/resweep-yolo11n yolo11n-int8dyn.onnx
# Time on 2 cores, all 1000 images (131 cells a model): YOLOX-nano ~1.5 h with one thread beside
# other work, YOLO11n ~3.5 h, YOLOv8n/YOLOv10n ~9.5 h each (two processes of one thread).
# Shared data: $FIDELITY_SHARED (default ../shared). The store stays outside the repository.
# A run longer than a session on a machine that may not come back: the store's finished cells
# (their scores, without the detections) go to the scores file $SCORES (default
# reports/coco/resweep/<first model>.scores.json.gz) every $EXPORT_EVERY seconds (default
# 1800) and at the end; commit it. On a new machine the same line imports it into the new
# store first and resumes from there.
# Commit reports/coco and fidelity/data/prediction when the merge has run.
set -euo pipefail
cd "$(dirname "$0")/../.."
S=$(cd "${FIDELITY_SHARED:-../shared}" && pwd)
STORE=$1; shift
models=""
for m in "$@"; do models="${models:+$models,}$S/models/$m"; done
first=$(basename "${1%@*}" .onnx)
SCORES=${SCORES:-reports/coco/resweep/$first.scores.json.gz}
ANN="$S/coco/annotations/instances_val2017_subset.json"
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
if [ -f "$SCORES" ] && [ ! -f "$STORE/sweep.sqlite" ]; then
  python -m fidelity sweep --import-scores "$SCORES" --out "$STORE"
fi
sweep() {
  python -m fidelity sweep --models "$models" \
    --images "$S/coco/val2017" --annotations "$ANN" \
    --transforms all --targets 0,1,2,3,4,5,6,8,10,12,15,18,21,24 --threads "${THREADS:-1}" \
    --provider cpu --no-progress --out "$STORE"
}
export_scores() {
  mkdir -p "$(dirname "$SCORES")"
  python -m fidelity sweep --export-scores "$SCORES" --annotations "$ANN" --out "$STORE"
}
# PROCESSES=N: N sweep processes share the store (each claims its own cells); the merge waits
# for all of them.
others=()
for _ in $(seq 2 "${PROCESSES:-1}"); do sweep & others+=($!); done
(while sleep "${EXPORT_EVERY:-1800}"; do
   [ -f "$STORE/sweep.sqlite" ] && { export_scores || true; }
 done) &
exporter=$!
sweep
for pid in ${others[@]+"${others[@]}"}; do wait "$pid"; done
kill "$exporter" 2>/dev/null || true
export_scores
# The merge reads a copy of the current tables (an input is never written over), named by the
# commit it came from (the prediction table's provenance records the name and its SHA-256).
tmp=$(mktemp -d)
earlier="$tmp/reports-coco-tables-at-$(git rev-parse --short HEAD).json"
cp reports/coco/tables.json "$earlier"
python -m fidelity tables "$STORE" --earlier "$earlier" --out reports/coco \
  --prediction fidelity/data/prediction/coco1000-measured.json \
  --directional fidelity/data/prediction/coco1000-directional.json --no-progress
rm -rf "$tmp"
