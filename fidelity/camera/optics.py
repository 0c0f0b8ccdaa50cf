"""Camera optics: the lens's point-spread function (PSF), applied to the linear camera image.

An :class:`Optics` is one of :data:`OPTICS_KINDS` (the ``[optics]`` section of a camera file,
:mod:`fidelity.camera.model`). Its optical transfer function (OTF, :meth:`Optics.transfer`;
the MTF is its modulus, :meth:`Optics.mtf`) at a spatial frequency ``f`` in cycles per pixel:

``none``
    1 at every frequency: no blur (the image is returned unchanged, the same array).
``gaussian``
    A Gaussian PSF of standard deviation ``sigma_px`` pixels: ``exp(-2 pi^2 sigma^2 f^2)``.
``defocus``
    A uniform disc (geometric defocus, the blur circle) of radius ``radius_px`` pixels:
    ``2 J1(x) / x`` with ``x = 2 pi r f`` (first zero at ``f = 3.8317 / (2 pi r) = 0.6098 / r``;
    negative beyond it: contrast reversal).
``diffraction``
    The diffraction limit of an aberration-free lens with a circular aperture at f-number
    ``f_number``, light of ``wavelength_nm`` and pixels of ``pixel_pitch_um``:
    ``2 / pi (arccos v - v sqrt(1 - v^2))`` with ``v = f / f_c`` (0 for ``v >= 1``), the cutoff
    ``f_c = pitch / (lambda N)`` cycles per pixel (Goodman, *Introduction to Fourier Optics*,
    6.4).
``mtf``
    A measured MTF table ``(frequency cy/px, value)``, linearly interpolated, the last value
    held beyond the table (starts at (0, 1); frequencies strictly increasing; values in [0, 1]).
``psf``
    A measured PSF image (odd height and width, non-negative, normalised to sum 1, its centre
    pixel the optical axis); its transfer is its discrete-time Fourier transform.

The PSF is rotationally symmetric for all kinds but ``psf``: its 2-D transfer at ``(fx, fy)``
is the 1-D one at ``sqrt(fx^2 + fy^2)``.

:meth:`Optics.apply` convolves a linear image ``(H, W, C)`` (or ``(H, W)``) with the PSF, each
channel alike, with the image's edges reflected (half-sample symmetric: ``d c b a | a b c d |
d c b a``, so a blur keeps the image's mean):

- ``gaussian``: a separable kernel sampled at the pixel centres, ``exp(-n^2 / (2 sigma^2))``
  for ``|n| <= ceil(4 sigma)``, normalised to sum 1 (:meth:`Optics.kernel_1d`). Its discrete
  Fourier transform is the Gaussian's MTF periodised by the sampling (Poisson summation): within
  1e-3 of ``exp(-2 pi^2 sigma^2 f^2)`` up to the Nyquist frequency for ``sigma >= 1.2`` px; a
  narrower Gaussian is not band-limited to the pixel grid and its sampled kernel passes more
  than the continuous MTF near Nyquist (at 0.5 px, 0.58 instead of 0.29 at 0.5 cy/px).
- the others: multiplication by the transfer in the Fourier domain of the symmetrically
  extended ``(2H, 2W)`` image (the PSF image's own DFT for ``psf``).

The blur is a filter on the sampled image whose transfer is the lens's: the pixel's own
aperture (a 1 px box, MTF ``sinc(f)``) is not added to it, so the closed-form chart's edges,
which lie on pixel boundaries, stay steps of the lens PSF alone. An erf fitted to the pixel
values of such a blurred step gives ``sqrt(sigma^2 - 1/12)`` (the sampling's Sheppard term,
1.9 % low at 1.5 px; tests/camera/test_optics.py).

All lengths are in pixels of the rendered image (``sigma_px``, ``radius_px``; the pitch in
micrometres only enters the diffraction cutoff).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fidelity.core.errors import InvalidValueError
from fidelity.core.record import record

FloatArray = NDArray[np.float64]

#: The PSF kinds of an :class:`Optics` (module docstring).
OPTICS_KINDS: tuple[str, ...] = ("none", "gaussian", "defocus", "diffraction", "mtf", "psf")
#: Half-width of the Gaussian kernel in standard deviations.
GAUSSIAN_RADIUS_SIGMAS: float = 4.0
#: First zero of the Bessel function J1 (the defocus disc's first MTF zero is at
#: ``J1_FIRST_ZERO / (2 pi r)`` cycles per pixel).
J1_FIRST_ZERO: float = 3.831705970207512


@record
class Optics:
    """The lens's point-spread function (module docstring).

    Attributes
    ----------
    kind
        One of :data:`OPTICS_KINDS`; ``"none"`` (the default) leaves the image unchanged.
    sigma_px
        ``gaussian``: the PSF's standard deviation in pixels, >= 0.
    radius_px
        ``defocus``: the blur disc's radius in pixels, >= 0.
    f_number
        ``diffraction``: the lens's f-number N (focal length / aperture diameter), > 0.
    wavelength_nm
        ``diffraction``: the wavelength in nanometres, > 0 (default 550, mid-visible).
    pixel_pitch_um
        ``diffraction``: the pixel pitch in micrometres, > 0.
    mtf_table
        ``mtf``: ``(frequency cy/px, MTF)`` points, starting at (0, 1), frequencies strictly
        increasing, values in [0, 1].
    psf
        ``psf``: the PSF image's rows (odd height and width, non-negative, sum 1).
    source
        Where a measured table or PSF was read from (a file's path; "" when inline or none).
    """

    kind: str = "none"
    sigma_px: float = 0.0
    radius_px: float = 0.0
    f_number: float | None = None
    wavelength_nm: float = 550.0
    pixel_pitch_um: float | None = None
    mtf_table: tuple[tuple[float, float], ...] | None = None
    psf: tuple[tuple[float, ...], ...] | None = None
    source: str = ""

    def __post_init__(self) -> None:
        problem = optics_problem(self)
        if problem is not None:
            raise InvalidValueError(f"optics {self.kind}: {problem}")

    @property
    def cutoff(self) -> float:
        """``diffraction``: the cutoff frequency ``pitch / (lambda N)`` in cycles per pixel
        (``inf`` for the other kinds)."""
        if self.kind != "diffraction" or self.f_number is None or self.pixel_pitch_um is None:
            return math.inf
        return self.pixel_pitch_um * 1e3 / (self.wavelength_nm * self.f_number)

    def transfer(self, f: ArrayLike) -> FloatArray:
        """The optical transfer function at radial frequencies ``f`` (cycles per pixel, >= 0).

        Parameters
        ----------
        f
            Spatial frequencies in cycles per pixel, any shape (negative values are read as
            their modulus).

        Returns
        -------
        numpy.ndarray
            The OTF (real: every PSF here is symmetric; ``psf`` gives the real part of its
            DTFT along the rows), 1 at ``f = 0``, the shape of ``f``. Negative where a
            defocus disc reverses contrast.
        """
        fr = np.abs(np.asarray(f, dtype=np.float64))
        if self.kind == "none":
            return np.ones_like(fr)
        if self.kind == "gaussian":
            out: FloatArray = np.exp(-2.0 * math.pi ** 2 * self.sigma_px ** 2 * fr ** 2)
            return out
        if self.kind == "defocus":
            return _disc_transfer(fr, self.radius_px)
        if self.kind == "diffraction":
            return diffraction_mtf(fr, self.cutoff)
        if self.kind == "mtf":
            table = np.asarray(self.mtf_table, dtype=np.float64)
            interp: FloatArray = np.interp(fr, table[:, 0], table[:, 1])
            return interp
        # psf: the DTFT of the line spread function (the PSF summed over its rows)
        lsf = self.kernel().sum(axis=0)
        n = np.arange(lsf.size) - lsf.size // 2
        phase = np.exp(-2j * math.pi * fr[..., None] * n)
        dtft: FloatArray = np.real(phase @ lsf)
        return dtft

    def mtf(self, f: ArrayLike) -> FloatArray:
        """The modulation transfer function ``|OTF|`` at frequencies ``f`` (cycles per pixel).

        Parameters
        ----------
        f
            Spatial frequencies in cycles per pixel, any shape.

        Returns
        -------
        numpy.ndarray
            The MTF in [0, 1], 1 at ``f = 0``, the shape of ``f``.
        """
        out: FloatArray = np.abs(self.transfer(f))
        return out

    def kernel_1d(self) -> FloatArray:
        """``gaussian``: the separable kernel, ``exp(-n^2 / (2 sigma^2))`` for integer ``|n| <=
        ceil(4 sigma)``, normalised to sum 1 (``[1.0]`` for sigma = 0).

        Returns
        -------
        numpy.ndarray
            The kernel, odd length ``2 ceil(4 sigma) + 1``, symmetric, sum 1.

        Raises
        ------
        InvalidValueError
            The optics is not ``gaussian``.
        """
        if self.kind != "gaussian":
            raise InvalidValueError(f"optics {self.kind}: only a gaussian has a separable kernel")
        if self.sigma_px == 0:
            return np.ones(1)
        r = math.ceil(GAUSSIAN_RADIUS_SIGMAS * self.sigma_px)
        n = np.arange(-r, r + 1, dtype=np.float64)
        g = np.exp(-(n ** 2) / (2.0 * self.sigma_px ** 2))
        out: FloatArray = g / g.sum()
        return out

    def kernel(self, size: int | None = None) -> FloatArray:
        """The PSF as a 2-D kernel normalised to sum 1, centred on its middle pixel.

        Parameters
        ----------
        size
            Odd side in pixels of the kernel of the Fourier kinds (``defocus``,
            ``diffraction``, ``mtf``: the inverse DFT of the transfer on a ``size`` x ``size``
            grid); None: ``2 ceil(4 r) + 1`` for a disc of radius r, ``2 ceil(8 / f_c) + 1``
            for diffraction, 65 for a table (at least 3). ``gaussian`` and ``psf`` ignore it.

        Returns
        -------
        numpy.ndarray
            ``(k, k)`` (``(kh, kw)`` for ``psf``), sum 1; ``[[1.0]]`` for ``none``.
        """
        if self.kind == "none":
            return np.ones((1, 1))
        if self.kind == "gaussian":
            g = self.kernel_1d()
            outer: FloatArray = np.outer(g, g)
            return outer
        if self.kind == "psf":
            k = np.asarray(self.psf, dtype=np.float64)
            normalised: FloatArray = k / k.sum()
            return normalised
        if size is None:
            if self.kind == "defocus":
                size = 2 * math.ceil(4 * max(self.radius_px, 1.0)) + 1
            elif self.kind == "diffraction":
                size = 2 * math.ceil(8.0 / min(self.cutoff, 1.0)) + 1
            else:
                size = 65
        size = max(3, int(size) | 1)
        fy = np.fft.fftfreq(size)[:, None]
        fx = np.fft.fftfreq(size)[None, :]
        k = np.real(np.fft.ifft2(self.transfer(np.hypot(fx, fy))))
        k = np.fft.fftshift(k)
        out: FloatArray = k / k.sum()
        return out

    def apply(self, image: ArrayLike) -> FloatArray:
        """``image`` convolved with the PSF, edges reflected (module docstring).

        Parameters
        ----------
        image
            A linear image ``(H, W)`` or ``(H, W, C)`` (every channel blurred alike), finite.

        Returns
        -------
        numpy.ndarray
            The blurred image, float64, the shape of ``image``, its mean kept (to rounding)
            by every symmetric PSF; for ``none`` the input as it is (not copied when it is
            already float64).

        Raises
        ------
        InvalidValueError
            An image that is not 2-D or 3-D, or a PSF image larger than twice the image.
        """
        img = np.asarray(image, dtype=np.float64)
        if img.ndim not in (2, 3):
            raise InvalidValueError(f"optics: expected an (H, W) or (H, W, C) image, got shape "
                                    f"{img.shape}")
        if self.kind == "none":
            return img
        if self.kind == "gaussian":
            g = self.kernel_1d()
            return _convolve_axis(_convolve_axis(img, g, 0), g, 1)
        h, w = img.shape[:2]
        ext = np.concatenate([img, img[::-1]], axis=0)
        ext = np.concatenate([ext, ext[:, ::-1]], axis=1)
        if self.kind == "psf":
            k = self.kernel()
            kh, kw = k.shape
            if kh > 2 * h or kw > 2 * w:
                raise InvalidValueError(f"optics psf: the PSF ({kh} x {kw} px) is larger than "
                                        f"twice the image ({h} x {w} px)")
            grid = np.zeros((2 * h, 2 * w))
            grid[:kh, :kw] = k
            otf: NDArray[np.complex128] | FloatArray = np.fft.rfft2(
                np.roll(grid, (-(kh // 2), -(kw // 2)), axis=(0, 1)))
        else:
            fy = np.fft.fftfreq(2 * h)[:, None]
            fx = np.fft.rfftfreq(2 * w)[None, :]
            otf = self.transfer(np.hypot(fx, fy))
        spectrum = np.fft.rfft2(ext, axes=(0, 1))
        if img.ndim == 3:
            otf = otf[..., None]
        out = np.fft.irfft2(spectrum * otf, s=(2 * h, 2 * w), axes=(0, 1))
        blurred: FloatArray = np.ascontiguousarray(out[:h, :w])
        return blurred


def diffraction_mtf(f: ArrayLike, cutoff: float) -> FloatArray:
    """The diffraction-limited MTF of a circular aperture (incoherent light).

    Parameters
    ----------
    f
        Spatial frequencies, any shape, in the unit of ``cutoff`` (cycles per pixel here).
    cutoff
        The cutoff frequency ``f_c = 1 / (lambda N)`` (here ``pitch / (lambda N)`` cycles per
        pixel), > 0.

    Returns
    -------
    numpy.ndarray
        ``2 / pi (arccos v - v sqrt(1 - v^2))`` with ``v = |f| / f_c``, 0 for ``v >= 1``.
    """
    v = np.clip(np.abs(np.asarray(f, dtype=np.float64)) / cutoff, 0.0, 1.0)
    out: FloatArray = 2.0 / math.pi * (np.arccos(v) - v * np.sqrt(1.0 - v ** 2))
    return out


def _disc_transfer(f: FloatArray, radius: float) -> FloatArray:
    """``2 J1(x) / x``, ``x = 2 pi r f`` (1 at x = 0): the OTF of a uniform disc."""
    from scipy.special import j1

    x = 2.0 * math.pi * radius * f
    small = x < 1e-8
    safe = np.where(small, 1.0, x)
    out: FloatArray = np.where(small, 1.0, 2.0 * j1(safe) / safe)
    return out


def _convolve_axis(img: FloatArray, kernel: FloatArray, axis: int) -> FloatArray:
    """``img`` convolved along ``axis`` with the odd, symmetric ``kernel``, edges reflected
    half-sample symmetric (numpy's ``symmetric`` padding, repeated for a kernel longer than
    the image)."""
    r = kernel.size // 2
    if r == 0:
        scaled: FloatArray = img * kernel[0]
        return scaled
    pad = [(0, 0)] * img.ndim
    pad[axis] = (r, r)
    padded = np.pad(img, pad, mode="symmetric")
    n = img.shape[axis]
    out = np.zeros_like(img)
    for k, weight in enumerate(kernel):
        out += weight * np.take(padded, np.arange(k, k + n), axis=axis)
    return out


def mtf_table_problem(table: ArrayLike) -> str | None:
    """Why ``(K, 2)`` points ``(frequency cy/px, MTF)`` are not an MTF table (None: they are).

    Parameters
    ----------
    table
        The points, ``(K, 2)``.

    Returns
    -------
    str or None
        The problem: fewer than 2 points, frequencies not strictly increasing (not monotone),
        a first point other than (0, 1), or a value outside [0, 1]; None for a table.
    """
    t = np.asarray(table, dtype=np.float64).reshape(-1, 2)
    if t.shape[0] < 2:
        return "needs at least 2 points [frequency cy/px, MTF]"
    if not np.all(np.diff(t[:, 0]) > 0):
        return "frequencies must be strictly increasing (monotone in frequency)"
    if t[0, 0] != 0.0 or t[0, 1] != 1.0:
        return f"must start at [0, 1] (MTF 1 at frequency 0), got [{t[0, 0]:g}, {t[0, 1]:g}]"
    if np.any(t[:, 1] < 0) or np.any(t[:, 1] > 1):
        return "MTF values must lie in [0, 1]"
    return None


def psf_problem(psf: ArrayLike) -> str | None:
    """Why an array is not a PSF image (None: it is one).

    Parameters
    ----------
    psf
        The candidate PSF image.

    Returns
    -------
    str or None
        The problem: not 2-D, an even height or width (no centre pixel), a value that is
        negative or not finite, or a zero sum; None for a PSF.
    """
    k = np.asarray(psf, dtype=np.float64)
    if k.ndim != 2 or k.size == 0:
        return f"must be a 2-D image, got shape {k.shape}"
    if k.shape[0] % 2 == 0 or k.shape[1] % 2 == 0:
        return f"must have an odd height and width (a centre pixel), got {k.shape[0]} x " \
               f"{k.shape[1]}"
    if not np.all(np.isfinite(k)) or np.any(k < 0):
        return "values must be finite and >= 0"
    if not k.sum() > 0:
        return "must have a positive sum"
    return None


def optics_problem(optics: Optics) -> str | None:
    """Why an :class:`Optics` is inconsistent (None: it is not).

    Parameters
    ----------
    optics
        The optics to check.

    Returns
    -------
    str or None
        An unknown kind (the known ones listed), a negative or non-finite length, a missing or
        non-positive diffraction parameter, an invalid MTF table (:func:`mtf_table_problem`)
        or PSF image (:func:`psf_problem`); None when consistent.
    """
    if optics.kind not in OPTICS_KINDS:
        return f"kind must be one of {', '.join(OPTICS_KINDS)}, got {optics.kind!r}"
    for name in ("sigma_px", "radius_px"):
        v = getattr(optics, name)
        if not (math.isfinite(v) and v >= 0):
            return f"{name} must be a finite number >= 0, got {v!r}"
    if optics.kind == "diffraction":
        for name in ("f_number", "wavelength_nm", "pixel_pitch_um"):
            v = getattr(optics, name)
            if v is None or not (math.isfinite(v) and v > 0):
                return f"{name} must be a finite number > 0, got {v!r}"
    if optics.kind == "mtf":
        if optics.mtf_table is None:
            return "an MTF table is required"
        return mtf_table_problem(optics.mtf_table)
    if optics.kind == "psf":
        if optics.psf is None:
            return "a PSF image is required"
        return psf_problem(optics.psf)
    return None


def read_mtf_file(path: str) -> FloatArray:
    """Read an MTF table file: lines of ``frequency (cy/px), MTF`` separated by a comma,
    semicolon, tab or spaces; an optional header line; ``#`` comments.

    Parameters
    ----------
    path
        The file's path.

    Returns
    -------
    numpy.ndarray
        The ``(K, 2)`` table as read (not yet checked: :func:`mtf_table_problem`).

    Raises
    ------
    InvalidValueError
        A file that cannot be read, a line that is not 2 numbers, or a value not finite.
    """
    rows: list[list[float]] = []
    try:
        with open(path, encoding="utf-8") as fh:
            lines = fh.read().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidValueError(f"{path}: cannot read the MTF table ({exc})") from None
    for lineno, line in enumerate(lines, start=1):
        s = line.split("#", 1)[0].replace(",", " ").replace(";", " ").strip()
        if not s:
            continue
        try:
            nums = [float(v) for v in s.split()]
        except ValueError:
            if not rows:  # a header
                continue
            raise InvalidValueError(f"{path}: line {lineno}: not numbers: {line.strip()!r}"
                                    ) from None
        if len(nums) != 2 or not all(math.isfinite(v) for v in nums):
            raise InvalidValueError(f"{path}: line {lineno}: expected 2 finite numbers "
                                    f"(frequency cy/px, MTF), got {line.strip()!r}")
        rows.append(nums)
    return np.asarray(rows, dtype=np.float64).reshape(-1, 2)


def read_psf_file(path: str) -> FloatArray:
    """Read a PSF image: a ``.npy`` array, or a text grid (``.csv``/``.txt``: rows of numbers
    separated by commas, semicolons, tabs or spaces; ``#`` comments).

    Parameters
    ----------
    path
        The file's path.

    Returns
    -------
    numpy.ndarray
        The image as read (not yet checked: :func:`psf_problem`).

    Raises
    ------
    InvalidValueError
        A file that cannot be read or parsed (the message says why).
    """
    try:
        if path.lower().endswith(".npy"):
            arr: FloatArray = np.asarray(np.load(path, allow_pickle=False), dtype=np.float64)
            return arr
        rows = []
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                s = line.split("#", 1)[0].replace(",", " ").replace(";", " ").strip()
                if s:
                    rows.append([float(v) for v in s.split()])
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise InvalidValueError(f"{path}: cannot read the PSF image ({exc})") from None
    if not rows or len({len(r) for r in rows}) != 1:
        raise InvalidValueError(f"{path}: the PSF image must be rows of equally many numbers")
    return np.asarray(rows, dtype=np.float64)


__all__ = [
    "GAUSSIAN_RADIUS_SIGMAS",
    "J1_FIRST_ZERO",
    "OPTICS_KINDS",
    "Optics",
    "diffraction_mtf",
    "mtf_table_problem",
    "optics_problem",
    "psf_problem",
    "read_mtf_file",
    "read_psf_file",
]
