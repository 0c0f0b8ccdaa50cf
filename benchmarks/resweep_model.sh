#!/usr/bin/env bash
# Re-measure detectors of the shipped COCO tables with this version's code, one store per run,
# and merge them into reports/coco and the shipped prediction tables, keeping the detectors not
# re-measured as they were (fidelity tables --earlier). Resumable: rerun the same line.
#   benchmarks/resweep_model.sh STORE MODEL.onnx[@N] [MODEL.onnx[@N] ...]
# e.g. PROCESSES=2 benchmarks/resweep_model.sh ~/.cache/fidelity/resweep-yolo11n yolo11n-int8dyn.onnx
# Time on 2 cores, all 1000 images (131 cells a model): YOLOX-nano ~1.5 h with one thread beside
# other work, YOLO11n ~3.5 h, YOLOv8n/YOLOv10n ~6.5 h each with two threads (THREADS=2).
# Shared data: $FIDELITY_SHARED (default ../shared). The store stays outside the repository;
# commit reports/coco and fidelity/data/prediction when the merge has run.
set -euo pipefail
cd "$(dirname "$0")/.."
S=$(cd "${FIDELITY_SHARED:-../shared}" && pwd)
STORE=$1; shift
models=""
for m in "$@"; do models="${models:+$models,}$S/models/$m"; done
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
sweep() {
  python -m fidelity sweep --models "$models" \
    --images "$S/coco/val2017" --annotations "$S/coco/annotations/instances_val2017_subset.json" \
    --transforms all --targets 0,1,2,3,4,5,6,8,10,12,15,18,21,24 --threads "${THREADS:-1}" \
    --provider cpu --no-progress --out "$STORE"
}
# PROCESSES=N: N sweep processes share the store (each claims its own cells); the merge waits
# for all of them.
others=()
for _ in $(seq 2 "${PROCESSES:-1}"); do sweep & others+=($!); done
sweep
for pid in ${others[@]+"${others[@]}"}; do wait "$pid"; done
# The merge reads a copy of the current tables (an input is never written over), named by the
# commit it came from (the prediction table's provenance records the name and its SHA-256).
tmp=$(mktemp -d)
earlier="$tmp/reports-coco-tables-at-$(git rev-parse --short HEAD).json"
cp reports/coco/tables.json "$earlier"
python -m fidelity tables "$STORE" --earlier "$earlier" --out reports/coco \
  --prediction fidelity/data/prediction/coco1000-measured.json \
  --directional fidelity/data/prediction/coco1000-directional.json --no-progress
rm -rf "$tmp"
