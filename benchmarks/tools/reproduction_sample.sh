#!/usr/bin/env bash
# The reproduction sample: the same sweep cells, on the same images, run on two machines, to
# compare their detections and scores (python -m benchmarks.tools.cross_machine digest, then
# compare --stores). Run it on each machine from the repository root:
#
#   benchmarks/tools/reproduction_sample.sh DATA OUT [PYTHON]
#
# DATA holds val2017/ (the images that annotations.json annotates) and models/MODEL.onnx for
# each of MODELS (default "yolov8n-int8dyn yolox_nano"); OUT gets machine.txt, one log and one
# store copy (MODEL.sqlite) per detector, and cuda.log (what --provider cuda does there with
# the first). Cells: the baseline and hue, pull_mean, contrast-dec, gamma-inc at ΔE 6 and 24
# (9 a detector), on the first LIMIT (250) annotated images by id, one onnxruntime thread, the
# CPU provider, the pycocotools scorer.
# PROCESSES sweep processes per detector share its cells through the store's claims; each
# sweep process stops after SWEEP_SECONDS (the copies are still made).
set -u
data=${1:?DATA folder}
out=${2:?OUT folder}
py=${3:-python3}
procs=${PROCESSES:-9}
read -r -a models <<< "${MODELS:-yolov8n-int8dyn yolox_nano}"
limit=${LIMIT:-250}
stores=${STORES:-/tmp/fidelity-reproduction}
mkdir -p "$out"
{
    date -u +%Y-%m-%dT%H:%M:%SZ
    echo "cpus: $(nproc)"
    lscpu | grep -E "^Model name|^Flags" | sed 's/^Flags:/flags:/'
    "$py" -c "import sys, numpy, cv2, PIL, onnxruntime as o
print('python', sys.version.split()[0]); print('numpy', numpy.__version__)
print('opencv', cv2.__version__); print('pillow', PIL.__version__)
print('onnxruntime', o.__version__, o.get_available_providers())"
} > "$out/machine.txt" 2>&1

run() {  # MODEL [--provider P] [extra options]
    local model=$1; shift
    timeout "${SWEEP_SECONDS:-3600}" "$py" -m fidelity sweep --models "$data/models/$model.onnx" \
        --images "$data/val2017" --annotations "$data/annotations.json" --limit "$limit" --threads 1 \
        --scorer pycocotools --no-progress "$@"
}
for model in "${models[@]}"; do
    for _ in $(seq "$procs"); do
        run "$model" --provider cpu --transforms hue,pull_mean,contrast-dec,gamma-inc \
            --targets 0,6,24 --out "$stores/$model" >> "$out/$model.log" 2>&1 &
    done
done
wait
run "${models[0]}" --provider cuda --transforms hue --targets 0 --limit 5 \
    --out "$stores/cuda" > "$out/cuda.log" 2>&1
echo "exit $?" >> "$out/cuda.log"
for model in "${models[@]}"; do
    "$py" -c "import sqlite3, sys
sqlite3.connect(sys.argv[1]).execute('VACUUM INTO ?', (sys.argv[2],))" \
        "$stores/$model/sweep.sqlite" "$out/$model.sqlite"
done
