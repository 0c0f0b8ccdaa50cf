# camera-fidelity with every extra and the system libraries it needs:
#   libllvm19 for Mitsuba 3's llvm_* variants (Dr.Jit's JIT). OpenCV is the headless contrib
#   build (cv2.mcc): it needs no libGL.
#
#   docker build -t camera-fidelity .
#   docker run --rm -v "$PWD:/work" -w /work camera-fidelity gate render.exr --max-delta-e 3
FROM python:3.11-slim-bookworm

RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
      libllvm19 \
 && rm -rf /var/lib/apt/lists/*

ENV PIP_NO_CACHE_DIR=1 \
    PYTHONDONTWRITEBYTECODE=1

WORKDIR /opt/camera-fidelity
COPY pyproject.toml README.md ./
COPY fidelity ./fidelity
COPY charts ./charts
COPY scenes ./scenes
COPY cameras ./cameras
RUN pip install ".[render,coco]" && fidelity info --no-probe

WORKDIR /work
ENTRYPOINT ["fidelity"]
CMD ["check"]
