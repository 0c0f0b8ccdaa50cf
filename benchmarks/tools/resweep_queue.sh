#!/usr/bin/env bash
# The re-sweeps still to do (issue 32), one detector after the other, each with
# benchmarks/tools/resweep_model.sh: its own store ($RESWEEP_STORES/resweep-<detector>, default under
# ~/.cache/fidelity), its scores file exported as it goes and committed by hand, and its merge
# into reports/coco and the shipped prediction tables when it is done. Resumable: rerun the same
# line; a detector whose store is complete only merges again (the same tables), then the next
# one starts, so the machine never waits between two detectors for someone to start the next.
#   PROCESSES=2 benchmarks/tools/resweep_queue.sh           # default: YOLOX-nano and YOLO11n
#       again (measured with this preprocessing on machines that are gone: their scores files,
#       so that every shipped row can be rebuilt without a store; both done and merged
#       2026-11-29: rerun, it only merges again); YOLOv8n's and YOLOv10n's re-sweeps are merged
#       (2026-11-28, 2026-11-29) and every scores file is committed
#   RESWEEP_MODELS="yolox_nano yolo11n-int8dyn" benchmarks/tools/resweep_queue.sh
# After each merge: python -m benchmarks.tools.after_resweep (see benchmarks/tools/after_resweep.py).
set -euo pipefail
cd "$(dirname "$0")/../.."
stores=${RESWEEP_STORES:-$HOME/.cache/fidelity}
for model in ${RESWEEP_MODELS:-yolox_nano yolo11n-int8dyn}; do
  benchmarks/tools/resweep_model.sh "$stores/resweep-${model%-int8dyn}" "$model.onnx"
done
