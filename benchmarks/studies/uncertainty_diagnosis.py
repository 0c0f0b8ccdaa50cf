"""Why the stated u under-covered at 12 MP (issue 59): per capture of
:mod:`benchmarks.studies.uncertainty_large`'s photo, the found corners, each patch's linear
mean, its stated standard uncertainty and design effects, and the budget's components, audited
with the corners found and with the true corners given; then the trial-to-trial spread of the
chart ΔE against the RMS stated u, each patch mean's spread against its stated u, and the
channels' correlation of the patch means across trials (pooled) against that of one window's
pixels and of its 16 x 16 block means.

    python -m benchmarks.studies.uncertainty_diagnosis 4000 3000 12
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from fidelity.colour import colorimetry as cm
from fidelity.measure import pixels as px
from tests.fixtures.photos import chart_geometry, photo, true_corners


def main(argv: list[str] | None = None) -> int:
    """Run the diagnosis (arguments: width, height, trials) and print its numbers."""
    w, h, trials = (int(a) for a in (argv if argv is not None else sys.argv[1:]))
    base = photo(w, h, seed=3, fill=0.9)[:, :, ::-1]
    seen: dict[str, Any] = {}
    shipped = px.image_uncertainty

    def capture(*a: Any, **k: Any) -> Any:
        seen["spreads"] = a[2]
        return shipped(*a, **k)

    px.image_uncertainty = capture  # type: ignore[assignment]
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "c.jpg"
        for t in range(trials):
            rng = np.random.default_rng((59, t))
            img = rng.standard_normal(base.shape, dtype=np.float32) * np.float32(3.0) + base
            cv2.imwrite(str(path), np.clip(np.rint(img), 0, 255).astype(np.uint8),
                        [cv2.IMWRITE_JPEG_QUALITY, 92])
            row = {}
            for mode, corners in (("found", None), ("fixed", true_corners(w, h, 0.9))):
                m = px.measure_image(path, corners)
                assert m.uncertainty is not None and m.linear_means is not None
                row[mode] = {"de": m.measurement.mean_delta_e, "u": m.uncertainty.combined,
                             "corners": np.asarray(m.location.corners).tolist(),
                             "means": np.asarray(m.linear_means).tolist(),
                             "u_patch": [float(np.sqrt(np.trace(s.covariance / s.count)))
                                         * float(np.sqrt(np.mean(s.design)))
                                         if s.design is not None else 0.0
                                         for s in seen["spreads"]]}
            rows.append(row)
    de = np.array([r["found"]["de"] for r in rows])
    u = np.array([r["found"]["u"] for r in rows])
    means = np.array([r["found"]["means"] for r in rows])
    corners = np.array([r["found"]["corners"] for r in rows])
    fixed = np.array([r["fixed"]["de"] for r in rows])
    z = (means - means.mean(0)) / means.std(0, ddof=1)
    pooled = np.einsum("tki,tkj->ij", z, z) / (trials - 1) / z.shape[1]
    print(f"{w}x{h}, {trials} trials: sd of chart ΔE {de.std(ddof=1):.5f}, RMS stated u "
          f"{np.sqrt(np.mean(u ** 2)):.5f}; corners' sd {corners.std(0, ddof=1).max():.2g} px; "
          f"largest |ΔE found - ΔE true corners| {np.abs(de - fixed).max():.2g}")
    print("channels' correlation of the patch means across trials (pooled):",
          np.round(pooled[np.triu_indices(3, 1)], 2).tolist())
    rng = np.random.default_rng((59, 0))
    img = np.clip(np.rint(rng.standard_normal(base.shape).astype(np.float32) * 3 + base), 0,
                  255).astype(np.uint8)
    dec = cv2.imdecode(cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 92])[1], 1)
    x0, y0, pitch, patch = chart_geometry(w, h, 0.9)
    side = (pitch // 2) // 16 * 16
    for k in (0, 7, 14):
        r, c = divmod(k, 6)
        ys, xs = y0 + r * pitch + patch // 2 - side // 2, x0 + c * pitch + patch // 2 - side // 2
        win = cm.linearize_srgb(dec[ys:ys + side, xs:xs + side, ::-1].astype(float) / 255)
        blocks = win.reshape(side // 16, 16, side // 16, 16, 3).mean((1, 3)).reshape(-1, 3)
        iu = np.triu_indices(3, 1)
        print(f"patch {k + 1}: pixels' channel correlation "
              f"{np.round(np.corrcoef(win.reshape(-1, 3), rowvar=False)[iu], 2).tolist()}, "
              f"block means' {np.round(np.corrcoef(blocks, rowvar=False)[iu], 2).tolist()}")
    out = Path("/tmp") / f"uncertainty_diagnosis_{w}x{h}.json"
    out.write_text(json.dumps(rows) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
