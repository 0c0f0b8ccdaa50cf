"""Sample the common view transforms into ``fidelity/data/view-transforms.json``, the tone
curves the cause model of a chart error (:mod:`fidelity.colour.diagnosis`) names.

Each view transform (a view and look of an OpenColorIO config, scene-linear Rec.709 in,
display sRGB out) is applied with PyOpenColorIO to a neutral ramp from 0.18 x 2^-12 to
0.18 x 2^10 in quarter stops and decoded with the IEC 61966-2-1 curve, as an audit reads the
PNG: its *neutral curve* (display-linear output per scene-linear input). Colours are not
neutral: a view transform such as AgX mixes the channels before and after its curve, so each
entry also gets an ``inset`` and an ``outset`` 3 x 3 matrix (rows adding up to 1, so that
neutrals keep the curve) with which ``outset @ curve(inset @ rgb)``, the curve per channel,
comes closest (least squares in CIELAB) to the transform on a training set: the 24 patches of
the chart at five exposures and 400 random colours. ``fit_delta_e`` states how close, in
mean and max CIEDE2000 over the 24 patches at exposure 1.

Usage: python -m benchmarks.tools.view_transforms CONFIG.ocio [--out fidelity/data/view-transforms.json]
       (CONFIG: Blender's datafiles/colormanagement/config.ocio, e.g. from the bpy wheel:
       .venv-blender/lib/python3.11/site-packages/bpy/5.0/datafiles/colormanagement/config.ocio)
"""

from __future__ import annotations

import argparse
import hashlib
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_reference

#: (name, family, view, look) of every transform sampled; looks of Blender's config.
TRANSFORMS: tuple[tuple[str, str, str, str], ...] = (
    *((f"Standard, {look}", "standard", "Standard", look) for look in (
        "Very High Contrast", "High Contrast", "Medium High Contrast", "Medium Low Contrast",
        "Low Contrast", "Very Low Contrast")),
    ("Filmic", "filmic", "Filmic", ""),
    *((f"Filmic, {look}", "filmic", "Filmic", look) for look in (
        "Very High Contrast", "High Contrast", "Medium High Contrast", "Medium Low Contrast",
        "Low Contrast", "Very Low Contrast")),
    ("AgX", "agx", "AgX", ""),
    *((f"AgX, {look.removeprefix('AgX - ')}", "agx", "AgX", look) for look in (
        "AgX - Punchy", "AgX - Very High Contrast", "AgX - High Contrast",
        "AgX - Medium High Contrast", "AgX - Medium Low Contrast", "AgX - Low Contrast",
        "AgX - Very Low Contrast")),
    ("ACES 1.3", "aces", "ACES 1.3", ""),
    ("ACES 2.0", "aces", "ACES 2.0", ""),
    ("Khronos PBR Neutral", "neutral", "Khronos PBR Neutral", ""),
)
#: The neutral ramp, in stops about 0.18.
STOPS = (-12.0, 10.0, 0.25)


def processor(config: Any, view: str, look: str) -> Callable[[np.ndarray], np.ndarray]:
    """Scene-linear Rec.709 (..., 3) -> display-linear sRGB through ``view`` and ``look``."""
    import PyOpenColorIO as ocio

    group = ocio.GroupTransform()
    if look:
        group.appendTransform(ocio.LookTransform(src="Linear Rec.709", dst="Linear Rec.709",
                                                 looks=look))
    group.appendTransform(ocio.DisplayViewTransform(src="Linear Rec.709", display="sRGB",
                                                    view=view))
    cpu = config.getProcessor(group).getDefaultCPUProcessor()

    def apply(rgb: np.ndarray) -> np.ndarray:
        a = np.ascontiguousarray(np.asarray(rgb, np.float32).reshape(-1, 3))
        cpu.applyRGB(a)
        return np.asarray(cm.linearize_srgb(a.astype(np.float64)), np.float64).reshape(
            np.shape(rgb))

    return apply


def _matrix(p: np.ndarray) -> np.ndarray:
    m = np.zeros((3, 3))
    m[~np.eye(3, dtype=bool)] = p
    m[np.diag_indices(3)] = 1.0 - m.sum(axis=1)
    return m


def fit_matrices(curve: Callable[[np.ndarray], np.ndarray], apply: Callable[[np.ndarray], np.ndarray],
                 train: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inset and outset matrices (rows adding up to 1) of the per-channel ``curve`` closest
    to ``apply`` on ``train`` (least squares in CIELAB)."""
    from scipy.optimize import least_squares

    target = cm.xyz_to_lab(cm.linear_srgb_to_xyz(apply(train)))

    def residual(p: np.ndarray) -> np.ndarray:
        out = curve(np.maximum(train @ _matrix(p[:6]).T, 0.0)) @ _matrix(p[6:]).T
        return np.asarray(cm.xyz_to_lab(cm.linear_srgb_to_xyz(out)) - target).ravel()

    fit = least_squares(residual, np.zeros(12), x_scale=0.1)
    return _matrix(fit.x[:6]), _matrix(fit.x[6:])


def main(argv: list[str] | None = None) -> int:
    import PyOpenColorIO as ocio

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config", type=Path)
    ap.add_argument("--out", type=Path, default=Path("fidelity/data/view-transforms.json"))
    a = ap.parse_args(argv)
    config = ocio.Config.CreateFromFile(str(a.config))
    stops = np.arange(STOPS[0], STOPS[1] + STOPS[2] / 2, STOPS[2])
    ramp = 0.18 * 2.0 ** stops
    patches = np.maximum(np.asarray(cm.xyz_to_linear_srgb(cm.lab_to_xyz(
        load_reference("scene").lab)), np.float64), 0.0)
    rng = np.random.default_rng(0)
    train = np.concatenate([patches * k for k in (0.25, 0.5, 1.0, 2.0, 4.0)]
                           + [rng.uniform(0, 1, (400, 3)) ** 2.2 * rng.choice([0.25, 1, 4],
                                                                               (400, 1))])
    entries = []
    for name, family, view, look in TRANSFORMS:
        apply = processor(config, view, look)
        neutral = apply(np.repeat(ramp[:, None], 3, axis=1))[:, 1]
        log_y = np.log2(np.maximum(neutral, 1e-12))

        def curve(x: np.ndarray, log_y: np.ndarray = log_y) -> np.ndarray:
            u = np.log2(np.maximum(x, 1e-12) / 0.18)
            return np.asarray(2.0 ** np.interp(u, stops, log_y), np.float64)

        inset, outset = fit_matrices(curve, apply, train)
        got = curve(np.maximum(patches @ inset.T, 0.0)) @ outset.T
        de = cm.delta_e_2000(cm.xyz_to_lab(cm.linear_srgb_to_xyz(got)),
                             cm.xyz_to_lab(cm.linear_srgb_to_xyz(apply(patches))))
        entries.append({
            "name": name, "family": family, "view": view, "look": look or None,
            "neutral": [float(f"{v:.6g}") for v in neutral],
            "inset": [[round(float(v), 6) for v in row] for row in inset],
            "outset": [[round(float(v), 6) for v in row] for row in outset],
            "fit_delta_e": {"mean": round(float(de.mean()), 4), "max": round(float(de.max()), 4)},
        })
        print(f"{name:40s} grey -> {curve(np.array([0.18]))[0]:.4f}, white 1.0 -> "
              f"{curve(np.array([1.0]))[0]:.4f}; fit ΔE00 mean {de.mean():.3f} max {de.max():.3f}")
    doc = {
        "name": "view-transforms",
        "description": "Neutral tone curves of common view transforms (display-linear sRGB "
                       "output per scene-linear input, on a quarter-stop ramp about 0.18) and "
                       "the inset/outset matrices of their per-channel approximation "
                       "(fidelity.colour.diagnosis)",
        "stops": {"start": STOPS[0], "stop": STOPS[1], "step": STOPS[2], "about": 0.18},
        "provenance": {
            "generator": "benchmarks/tools/view_transforms.py",
            "config": a.config.name, "config_description": config.getDescription().strip()[:200],
            "config_sha256": hashlib.sha256(a.config.read_bytes()).hexdigest(),
            "opencolorio": ocio.__version__, "input": "Linear Rec.709 (scene-linear)",
            "display": "sRGB, decoded with the IEC 61966-2-1 curve",
            "training": "24 scene-reference patches (D65) x 0.25, 0.5, 1, 2, 4 and 400 random "
                        "colours (seed 0)",
        },
        "transforms": entries,
    }
    a.out.write_text(json.dumps(doc, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
