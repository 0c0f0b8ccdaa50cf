# camera-fidelity in a container. By default the core only, which is all `gate`, `audit`,
# `check` (closed form), `compare` and `predict` need; the full image adds the extras and the
# system library they need:
#   libllvm19 for Mitsuba 3's llvm_* variants (Dr.Jit's JIT). OpenCV is the headless contrib
#   build (cv2.mcc): it needs no libGL.
#
#   docker build -t camera-fidelity .                                   # the gate image
#   docker build -t camera-fidelity:full --build-arg EXTRAS=render,coco .
#   docker run --rm -v "$PWD:/work" -w /work camera-fidelity gate render.exr --max-delta-e 3
#
# The base image is pinned to a Python release (its Debian release named too); the process runs
# as an unprivileged user.
FROM python:3.11.11-slim-bookworm

ARG EXTRAS=""

RUN case ",${EXTRAS}," in *,render,*) \
      apt-get update \
      && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends libllvm19 \
      && rm -rf /var/lib/apt/lists/* ;; \
    esac

ENV PIP_NO_CACHE_DIR=1 \
    PYTHONDONTWRITEBYTECODE=1

WORKDIR /opt/camera-fidelity
COPY pyproject.toml README.md LICENSE ./
COPY fidelity ./fidelity
COPY charts ./charts
COPY scenes ./scenes
COPY cameras ./cameras
RUN pip install ".${EXTRAS:+[${EXTRAS}]}" && fidelity info --no-probe

RUN useradd --create-home --uid 10001 fidelity
USER fidelity
WORKDIR /work
ENTRYPOINT ["fidelity"]
CMD ["check"]
