"""fidelity: camera-sensor-model colour-fidelity checker for driving simulators.

Implements the SAFE-COLOR method (Damschen, Avula, Mohamad, IEEE IV 2025): colour error of a
simulated camera, measured as CIEDE2000 on a Macbeth ColorChecker, mapped to predicted object
detection loss.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("fidelity")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+source"

__all__ = ["__version__"]
