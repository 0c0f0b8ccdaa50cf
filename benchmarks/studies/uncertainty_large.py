"""Does the stated uncertainty still cover at 12 and 108 MP, where a window's statistics come
from a lattice of its whole blocks (issue 59, :func:`fidelity.measure.uncertainty.block_sample`)?

One synthetic photo (:func:`tests.fixtures.photos.photo`, the chart filling the frame,
``fill`` 0.9) captured ``trials`` times: each capture its own pixel noise (normal, ``noise``
codes), stored as a quality-92 JPEG, audited from the file (``fidelity.audit_image``: the chart
found, exposure fitted). Each capture is audited twice: as shipped (``sampled``) and with every
pixel of every window in its statistics (``all pixels``: ``SPREAD_SAMPLE_PIXELS`` set beyond any
window), so that the two stated u are compared on the same captures. Coverage as in
:mod:`benchmarks.studies.uncertainty_coverage` (fraction of the ΔE values within ±u / ±2u
of their mean).

    python -m benchmarks.studies.uncertainty_large --trials 50,50,20
    # -> reports/uncertainty/coverage_large.json and coverage_large.md
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.studies.uncertainty_coverage import OUT, coverage

SIZES = {"8 MP": (3264, 2448), "12 MP": (4000, 3000), "108 MP": (12000, 9000)}


def study(width: int, height: int, trials: int, noise: float) -> dict[str, Any]:
    import cv2

    import fidelity
    from fidelity.measure import uncertainty as unc
    from tests.fixtures.photos import photo

    base = photo(width, height, seed=3, fill=0.9)[:, :, ::-1]
    results: dict[str, list[tuple[float, float]]] = {"sampled": [], "all pixels": []}
    shipped = unc.SPREAD_SAMPLE_PIXELS
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "capture.jpg"
        for trial in range(trials):
            rng = np.random.default_rng((59, trial))
            img = rng.standard_normal(base.shape, dtype=np.float32)
            img *= np.float32(noise)
            img += base
            ok = cv2.imwrite(str(path), np.clip(np.rint(img), 0, 255).astype(np.uint8),
                             [cv2.IMWRITE_JPEG_QUALITY, 92])
            assert ok
            del img
            for mode, limit in (("sampled", shipped), ("all pixels", 1 << 62)):
                unc.SPREAD_SAMPLE_PIXELS = limit
                try:
                    report = fidelity.audit_image(path)
                finally:
                    unc.SPREAD_SAMPLE_PIXELS = shipped
                assert report.uncertainty is not None
                results[mode].append((report.mean_delta_e, report.uncertainty.combined))
    out: dict[str, Any] = {"size": f"{width}x{height}", "noise_codes": noise,
                           "seconds": time.perf_counter() - t0}
    for mode, rows in results.items():
        out[mode] = coverage([d for d, _ in rows], [u for _, u in rows])
    return out


def markdown(result: dict[str, Any]) -> str:
    lines = ["# Coverage of the stated u at 8, 12 and 108 MP (issue 59)", "",
             "Written by `python -m benchmarks.studies.uncertainty_large`. The chart filling "
             "the frame (synthetic photo, fill 0.9), each capture its own normal pixel noise, "
             "a quality-92 JPEG; each capture audited with the windows' statistics from the "
             "block lattice (sampled, as shipped) and from all pixels.", "",
             "| size | statistics | trials | mean ΔE00 | observed sd | RMS stated u | sd / u | "
             "within ±u | within ±2u |", "|---|---|---|---|---|---|---|---|---|"]
    for s in result["studies"]:
        for mode in ("sampled", "all pixels"):
            c = s[mode]
            lines.append(f"| {s['size']} | {mode} | {c['trials']} | {c['mean_delta_e']:.4f} | "
                         f"{c['observed_sd']:.5f} | {c['rms_u']:.5f} | "
                         f"{c['sd_over_rms_u']:.2f} | {100 * c['within_1u']:.0f} % | "
                         f"{100 * c['within_2u']:.0f} % |")
    se = ", ".join(f"{100 * s['sampled']['binomial_se_at_68']:.0f} % at 68 % and "
                   f"N = {s['sampled']['trials']}" for s in result["studies"])
    worst = max(100 * abs(s["sampled"]["rms_u"] / s["all pixels"]["rms_u"] - 1)
                for s in result["studies"])
    ratios = [s[m]["sd_over_rms_u"] for s in result["studies"] for m in ("sampled", "all pixels")]
    lo, hi = min(ratios), max(ratios)
    lines += ["", "Binomial standard error of a coverage fraction over N trials: "
              f"sqrt(p (1 - p) / N) ({se}). Largest difference of the two statistics' u: "
              f"{worst:.1f} %. sd / u from {lo:.2f} to {hi:.2f}."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", default="50,50,20", help="trials at 8, 12 and 108 MP")
    ap.add_argument("--noise", type=float, default=3.0, help="pixel noise sd, codes")
    args = ap.parse_args(argv)
    trials = [int(t) for t in args.trials.split(",")]
    studies = [study(w, h, n, args.noise) for (w, h), n in zip(SIZES.values(), trials,
                                                               strict=True) if n > 0]
    result = {"studies": studies}
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "coverage_large.json").write_text(json.dumps(result, indent=2) + "\n")
    (OUT / "coverage_large.md").write_text(markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
