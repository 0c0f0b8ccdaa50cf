"""Write the camera suite that validates the sharpness and noise verdict: ``cameras/properties``.

Each camera is one lens and sensor configuration (:data:`CONFIGS`) on one of two colour
renderings (:data:`COLOURS`): ``ideal``, the exact sRGB camera (CIE 1931 sensitivities, no
colour correction, sRGB tone curve, 12 bits: no colour error but its quantisation), and
``nikon``, the Nikon D5100 with auto exposure, white balance to the scene and a CCM fitted
by Cheung 2004 under D65 (the colour error of a good real camera); four configurations also
on ``wbd50``, the same camera balanced for D50 in a D65 scene (a larger colour error, as
``cameras/nikon5100-wb-d50.toml``). ``clean`` (no blur, no noise) gives each colour rendering
alone, the colour validation's own case. The lens's PSF is in pixels
of the COCO images (640 x 480, the detector's input scale); the full well is electrons at
raw 1 (white, for the ideal camera, at gain 1; 0.9 of white metered for the Nikon).

Low light, two ways: ``ev3`` underexposes a 20k e- sensor by 3 stops and does not gain the
image up (a dark, noisy picture); ``iso8`` and ``iso32`` expose correctly with 1/8 and 1/32
of the light gained up 8x and 32x, i.e. 2500 and 625 electrons at raw 1 for the same 20k e-
sensor (the model's full well is electrons at raw 1), its read noise 5 e- unchanged.

Usage: python -m benchmarks.studies.property_cameras [--out cameras/properties]
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fidelity.core.fileio import write_text_atomic

#: The colour renderings: name -> (description, the TOML of the colour stages).
COLOURS: Mapping[str, tuple[str, str]] = {
    "ideal": ("exact sRGB camera, sRGB tone curve, 12 bit (no colour error)", """\
[sensitivities]
source = "ideal"

[exposure]
{exposure}

[white_balance]
method = "illuminant"
illuminant = "scene"

[ccm]
method = "none"

[tone]
curve = "srgb"

[quantisation]
bits = 12
"""),
    "nikon": ("Nikon D5100, AWB, CCM Cheung 2004 (D65), sRGB, 12 bit (a real camera's colour "
              "error)", """\
[sensitivities]
source = "Nikon 5100 (NPL)"

[exposure]
{exposure}

[white_balance]
method = "illuminant"
illuminant = "scene"

[ccm]
method = "fit"
fit_method = "Cheung 2004"
fit_illuminant = "D65"

[tone]
curve = "srgb"

[quantisation]
bits = 12
"""),
    "wbd50": ("Nikon D5100, WB set for D50 in a D65 scene (too blue), the CCM of "
              "nikon5100-cheung-d65, sRGB, 12 bit (a larger colour error, chart dE00 about 6)",
                 """\
[sensitivities]
source = "Nikon 5100 (NPL)"

[exposure]
{exposure}

[white_balance]
method = "illuminant"
illuminant = "D50"

[ccm]
method = "matrix"
matrix = [[1.740658, -0.641055, -0.106938], [-0.157521, 1.657109, -0.494886], [0.061209, -0.546386, 1.477222]]

[tone]
curve = "srgb"

[quantisation]
bits = 12
"""),
}

#: Exposure of each colour rendering at normal light.
EXPOSURE: Mapping[str, str] = {"ideal": 'mode = "gain"\ngain = 1.0',
                               "nikon": 'mode = "auto"\ntarget = 0.9',
                               "wbd50": 'mode = "auto"\ntarget = 0.9'}
#: Three stops under (``ev3``), not gained up.
UNDEREXPOSED: Mapping[str, str] = {"ideal": 'mode = "gain"\ngain = 0.125',
                                   "nikon": 'mode = "auto"\ntarget = 0.1125',
                                   "wbd50": 'mode = "auto"\ntarget = 0.1125'}


#: The lens and sensor configurations: name -> (description, optics, noise, underexposed).
CONFIGS: Mapping[str, tuple[str, dict[str, Any] | None, dict[str, float] | None, bool]] = {
    "clean": ("no lens blur, no sensor noise (colour alone)", None, None, False),
    "gauss0.5": ("Gaussian lens blur 0.5 px", {"kind": "gaussian", "sigma_px": 0.5}, None, False),
    "gauss1.0": ("Gaussian lens blur 1 px", {"kind": "gaussian", "sigma_px": 1.0}, None, False),
    "gauss1.5": ("Gaussian lens blur 1.5 px", {"kind": "gaussian", "sigma_px": 1.5}, None, False),
    "gauss2.0": ("Gaussian lens blur 2 px", {"kind": "gaussian", "sigma_px": 2.0}, None, False),
    "gauss3.0": ("Gaussian lens blur 3 px", {"kind": "gaussian", "sigma_px": 3.0}, None, False),
    "defocus1.5": ("defocus disc of radius 1.5 px", {"kind": "defocus", "radius_px": 1.5},
                   None, False),
    "defocus3.0": ("defocus disc of radius 3 px", {"kind": "defocus", "radius_px": 3.0},
                   None, False),
    "fw30k-rn2": ("sensor: full well 30000 e-, read noise 2 e-", None,
                  {"full_well": 30000.0, "read_noise": 2.0}, False),
    "fw10k-rn5": ("sensor: full well 10000 e-, read noise 5 e-", None,
                  {"full_well": 10000.0, "read_noise": 5.0}, False),
    "fw5k-rn10": ("sensor: full well 5000 e-, read noise 10 e-", None,
                  {"full_well": 5000.0, "read_noise": 10.0}, False),
    "lowlight-ev3": ("low light: 20000 e-, read noise 5 e-, 3 stops underexposed, not gained up",
                     None, {"full_well": 20000.0, "read_noise": 5.0}, True),
    "lowlight-iso8": ("low light: 20000 e- sensor at 1/8 of the light gained up 8x (2500 e- "
                      "at raw 1), read noise 5 e-", None,
                      {"full_well": 2500.0, "read_noise": 5.0}, False),
    "lowlight-iso32": ("low light: 20000 e- sensor at 1/32 of the light gained up 32x (625 e- "
                       "at raw 1), read noise 5 e-", None,
                       {"full_well": 625.0, "read_noise": 5.0}, False),
    "gauss1.0-fw10k": ("Gaussian blur 1 px and full well 10000 e-, read noise 5 e-",
                       {"kind": "gaussian", "sigma_px": 1.0},
                       {"full_well": 10000.0, "read_noise": 5.0}, False),
    "gauss2.0-fw5k": ("Gaussian blur 2 px and full well 5000 e-, read noise 10 e-",
                      {"kind": "gaussian", "sigma_px": 2.0},
                      {"full_well": 5000.0, "read_noise": 10.0}, False),
    "gauss1.5-iso8": ("Gaussian blur 1.5 px in low light (2500 e- at raw 1, read noise 5 e-)",
                      {"kind": "gaussian", "sigma_px": 1.5},
                      {"full_well": 2500.0, "read_noise": 5.0}, False),
}


#: The configurations of each colour rendering (every one for ``ideal`` and ``nikon``).
COLOUR_CONFIGS: Mapping[str, tuple[str, ...]] = {
    "ideal": tuple(CONFIGS), "nikon": tuple(CONFIGS),
    "wbd50": ("clean", "gauss1.5", "fw5k-rn10", "gauss2.0-fw5k", "lowlight-iso8"),
}


def _value(v: Any) -> str:
    return f'"{v}"' if isinstance(v, str) else repr(float(v))


def camera_toml(colour: str, config: str) -> tuple[str, str]:
    """The file name and text of one camera of the suite."""
    cdesc, stages = COLOURS[colour]
    desc, optics, noise, under = CONFIGS[config]
    name = f"{colour}-{config}"
    exposure = (UNDEREXPOSED if under else EXPOSURE)[colour]
    lines = ["# Written by python -m benchmarks.studies.property_cameras: do not edit by hand.",
             f'name = "{name}"', f'description = "{cdesc}; {desc}"', "",
             stages.format(exposure=exposure).rstrip()]
    if optics:
        lines += ["", "[optics]", *(f"{k} = {_value(v)}" for k, v in optics.items())]
    if noise:
        lines += ["", "[noise]", *(f"{k} = {_value(v)}" for k, v in noise.items())]
    return f"{name}.toml", "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write every camera of the suite into ``--out`` (existing files of other names kept)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="cameras/properties")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    n = 0
    lines = ["# Camera suite for `fidelity validate --properties`", "",
             "Written by `python -m benchmarks.studies.property_cameras` (do not edit by hand); "
             "what each colour rendering and configuration models is in that script's "
             "docstring. The lens's PSF is in pixels of the COCO images, the full well in "
             "electrons at raw 1. Run: see docs/validation.md, \"Sharpness and noise\".", "",
             "| camera | what it is |", "|---|---|"]
    for colour, configs in COLOUR_CONFIGS.items():
        for config in configs:
            name, text = camera_toml(colour, config)
            write_text_atomic(out / name, text)
            lines.append(f"| {name[:-5]} | {COLOURS[colour][0]}; {CONFIGS[config][0]} |")
            n += 1
    write_text_atomic(out / "README.md", "\n".join(lines) + "\n")
    print(f"wrote {n} camera files and README.md to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
