"""The few colour-science datasets a camera check and an audit need, shipped as data.

``import colour`` (colour-science 0.4.7) imports ``colour.plotting`` and with it matplotlib and
scipy.interpolate: about a second of every command that touched it. The tables the default
paths read are copied here from colour-science, unchanged (``fidelity/data/colour-datasets.json``,
written by :func:`write_datasets`; ``tests/colour/test_datasets.py`` checks every number against
colour-science): the CIE 1931 2° observer, the built-in illuminants, the cameras of the built-in
camera models, the chromatic adaptation matrices and the primaries and whites of the RGB
colourspaces the command line names. Anything else is still read from colour-science, on demand.

Sources (as colour-science gives them): CIE 018:2019 / CIE 15:2018 (observer, illuminants D65,
D50, A, FL2, FL11, LED-B4); NPL camera sensitivities (Darrodi et al. 2015); Lam 1985 (Bradford),
CIECAM02 (CAT02), CAM16 (CAT16), Hunt-Pointer-Estevez (Von Kries), XYZ Scaling; the colourspace
specifications (IEC 61966-2-1, ITU-R BT.709/BT.2020, SMPTE EG 432-1, ACES S-2014-004 ...).

The validation's camera emulation fits on a few hundred reflectances, shipped the same way in
their own file (``training-reflectances.json.gz``, read only by the COCO pipeline): the
rawtoaces v1 training data (AMPAS), the CIE test colour samples (CIE 13.3-1995, CIE 224:2017),
the NIST CQS samples (Davis & Ohno 2010) and three ColourChecker sets (N Ohta, ISO 17321-1,
PMC), as colour-science tabulates them.
"""

from __future__ import annotations

import gzip
import json
import os
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fidelity.core.fileio import write_bytes_atomic, write_text_atomic
from fidelity.core.resources import resource_dir

#: The file the datasets ship in (package data).
DATA_FILE = "colour-datasets.json"
#: colour-science's name of the CIE 1931 2° standard observer.
CIE_1931 = "CIE 1931 2 Degree Standard Observer"
#: Illuminants shipped (colour-science ``SDS_ILLUMINANTS`` keys).
ILLUMINANTS: tuple[str, ...] = ("D65", "D50", "A", "FL2", "FL11", "LED-B4")
#: Camera sensitivities shipped (``MSDS_CAMERA_SENSITIVITIES`` keys).
CAMERAS: tuple[str, ...] = ("Nikon 5100 (NPL)", "Sigma SDMerill (NPL)")
#: Chromatic adaptation transforms shipped (``CHROMATIC_ADAPTATION_TRANSFORMS`` keys).
ADAPTATIONS: tuple[str, ...] = ("Bradford", "CAT02", "CAT16", "Von Kries", "XYZ Scaling")
#: RGB colourspaces shipped (``RGB_COLOURSPACES`` keys): the ones the command line names.
COLOURSPACES: tuple[str, ...] = ("sRGB", "ITU-R BT.709", "ITU-R BT.2020", "Display P3",
                                 "DCI-P3", "ACEScg", "ACES2065-1", "Adobe RGB (1998)")

FloatArray = NDArray[np.float64]

#: The file the training reflectances of the validation's emulation ship in (package data;
#: gzip, read only by :func:`training_reflectances`).
TRAINING_FILE = "training-reflectances.json.gz"
#: ColourChecker reflectance sets among the training reflectances (``SDS_COLOURCHECKERS``).
TRAINING_CHECKERS: tuple[str, ...] = ("ColorChecker N Ohta", "ISO 17321-1", "PMC")

#: One training reflectance: name, wavelengths (N,) nm and reflectance (N,), as tabulated.
Reflectance = tuple[str, FloatArray, FloatArray]


def data_path() -> Path:
    """Where the shipped datasets are."""
    return resource_dir("data") / DATA_FILE


@lru_cache(maxsize=1)
def _datasets() -> dict[str, Any]:
    data: dict[str, Any] = json.loads(data_path().read_text(encoding="utf-8"))
    return data


def _spectral(group: str, name: str) -> tuple[FloatArray, FloatArray]:
    item = _datasets()[group][name]
    return (np.asarray(item["wavelengths"], dtype=np.float64),
            np.asarray(item["values"], dtype=np.float64))


def cmfs_1931() -> tuple[FloatArray, FloatArray]:
    """The CIE 1931 2° standard observer: wavelengths (N,) nm and x̄, ȳ, z̄ (N, 3)."""
    return _spectral("cmfs", CIE_1931)


def illuminant(name: str) -> tuple[FloatArray, FloatArray] | None:
    """A shipped illuminant's relative SPD (wavelengths (N,) nm, values (N,)); None when
    ``name`` is not one of :data:`ILLUMINANTS`."""
    return _spectral("illuminants", name) if name in ILLUMINANTS else None


def camera_sensitivities(name: str) -> tuple[FloatArray, FloatArray] | None:
    """A shipped camera's R, G, B sensitivities (wavelengths (N,) nm, values (N, 3)); None when
    ``name`` is not one of :data:`CAMERAS`."""
    return _spectral("cameras", name) if name in CAMERAS else None


def adaptation_matrix(name: str) -> FloatArray | None:
    """The cone-response matrix of a chromatic adaptation transform (3, 3); None when ``name``
    is not one of :data:`ADAPTATIONS`."""
    if name not in ADAPTATIONS:
        return None
    return np.asarray(_datasets()["adaptations"][name], dtype=np.float64)


def colourspace(name: str) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """A shipped RGB colourspace's primaries (3, 2) and white (2,), CIE 1931 xy, and its RGB ->
    XYZ matrix (3, 3; the specification's own where it publishes one, as colour-science holds
    it); None when ``name`` is not one of :data:`COLOURSPACES`."""
    if name not in COLOURSPACES:
        return None
    item = _datasets()["colourspaces"][name]
    return (np.asarray(item["primaries"], dtype=np.float64),
            np.asarray(item["whitepoint"], dtype=np.float64),
            np.asarray(item["matrix_RGB_to_XYZ"], dtype=np.float64))


def training_reflectances() -> dict[str, list[Reflectance]]:
    """The training reflectances of the validation's emulation
    (:func:`fidelity.coco.emulation.training_reflectances`) by source, in colour-science's
    order, as tabulated (not resampled): ``rawtoaces v1 training data`` (190 samples), ``CIE
    TCS`` (CIE 13.3 / CIE 224 test colour samples), ``NIST CQS VS`` (the NIST colour quality
    scale's samples), ``ColourChecker sets`` (:data:`TRAINING_CHECKERS`)."""
    return {label: [(n, np.asarray(w, np.float64), np.asarray(v, np.float64))
                    for n, w, v in items] for label, items in _training().items()}


@lru_cache(maxsize=1)
def _training() -> dict[str, list[tuple[str, list[float], list[float]]]]:
    with gzip.open(resource_dir("data") / TRAINING_FILE, "rt", encoding="utf-8") as f:
        doc: dict[str, Any] = json.load(f)
    return {label: [(i["name"], i["wavelengths"], i["values"]) for i in items]
            for label, items in doc["sets"].items()}


def colour_science_training() -> dict[str, Any]:
    """The training reflectances as colour-science holds them now (imports ``colour``): the
    shipped file's content."""
    import colour

    def item(name: str, wavelengths: Any, values: Any) -> dict[str, Any]:
        return {"name": name, "wavelengths": np.asarray(wavelengths, np.float64).tolist(),
                "values": np.asarray(values, np.float64).tolist()}

    t = colour.characterisation.read_training_data_rawtoaces_v1()
    values = np.asarray(t.values, np.float64)
    sets: dict[str, list[dict[str, Any]]] = {
        "rawtoaces v1 training data": [item(str(n), t.wavelengths, values[:, k])
                                       for k, n in enumerate(t.labels)]}
    for label, group in (("CIE TCS", colour.quality.SDS_TCS),
                         ("NIST CQS VS", colour.quality.SDS_VS)):
        sets[label] = [item(f"{set_name} {k}", sd.wavelengths, sd.values)
                       for set_name, sds in group.items() for k, sd in sds.items()]
    sets["ColourChecker sets"] = [item(f"{set_name} {k}", sd.wavelengths, sd.values)
                                  for set_name in TRAINING_CHECKERS
                                  for k, sd in colour.SDS_COLOURCHECKERS[set_name].items()]
    return {"source": f"colour-science {colour.__version__}", "sets": sets}


def colour_science_datasets() -> dict[str, Any]:
    """The datasets as colour-science holds them now (imports ``colour``)."""
    import colour

    def spectral(sd: Any) -> dict[str, Any]:
        return {"wavelengths": np.asarray(sd.wavelengths, np.float64).tolist(),
                "values": np.asarray(sd.values, np.float64).tolist()}

    return {
        "source": f"colour-science {colour.__version__}",
        "cmfs": {CIE_1931: spectral(colour.MSDS_CMFS[CIE_1931])},
        "illuminants": {n: spectral(colour.SDS_ILLUMINANTS[n]) for n in ILLUMINANTS},
        "cameras": {n: spectral(colour.MSDS_CAMERA_SENSITIVITIES[n]) for n in CAMERAS},
        "adaptations": {n: np.asarray(colour.CHROMATIC_ADAPTATION_TRANSFORMS[n],
                                      np.float64).tolist() for n in ADAPTATIONS},
        "colourspaces": {n: {"primaries": np.asarray(colour.RGB_COLOURSPACES[n].primaries,
                                                     np.float64).tolist(),
                             "whitepoint": np.asarray(colour.RGB_COLOURSPACES[n].whitepoint,
                                                      np.float64).tolist(),
                             "matrix_RGB_to_XYZ": np.asarray(
                                 colour.RGB_COLOURSPACES[n].matrix_RGB_to_XYZ,
                                 np.float64).tolist()}
                         for n in COLOURSPACES},
    }


def write_datasets(path: str | os.PathLike[str] | None = None) -> Path:
    """Write :func:`colour_science_datasets` to ``path`` (default: the shipped file), and
    :func:`colour_science_training` beside it (:data:`TRAINING_FILE`), atomically."""
    out = write_text_atomic(path or data_path(),
                            json.dumps(colour_science_datasets(), separators=(",", ":")) + "\n")
    text = json.dumps(colour_science_training(), separators=(",", ":")) + "\n"
    write_bytes_atomic(out.parent / TRAINING_FILE,
                       gzip.compress(text.encode("utf-8"), compresslevel=9, mtime=0))
    return out


__all__ = [
    "ADAPTATIONS",
    "CAMERAS",
    "CIE_1931",
    "COLOURSPACES",
    "DATA_FILE",
    "ILLUMINANTS",
    "TRAINING_CHECKERS",
    "TRAINING_FILE",
    "Reflectance",
    "adaptation_matrix",
    "camera_sensitivities",
    "cmfs_1931",
    "colour_science_datasets",
    "colour_science_training",
    "colourspace",
    "data_path",
    "illuminant",
    "training_reflectances",
    "write_datasets",
]

if __name__ == "__main__":  # python -m fidelity.colour.datasets [PATH]
    import sys

    print(write_datasets(sys.argv[1] if len(sys.argv) > 1 else None))
