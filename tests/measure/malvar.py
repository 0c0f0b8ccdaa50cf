"""Malvar, He & Cutler's demosaicing kernels (ICASSP 2004, Fig. 2), written out from the paper
(not from colour-demosaicing), for the closed forms of a Bayer mosaic's demosaiced channels.

On an achromatic scene every CFA site holds the same value, so each demosaiced pixel is a fixed
5 x 5 kernel of its site type applied to the full-resolution image: the channel's response is
the mean of its four site types' kernels (the e-SFR bins all of them alike), and white noise of
sigma per site leaves a pixel of that site type the variance ``sigma^2 sum(k^2)``.
"""

from __future__ import annotations

import math

import numpy as np

_ID = np.zeros((5, 5))
_ID[2, 2] = 1.0
#: G at an R or B site.
G_AT_RB = np.array([[0, 0, -1, 0, 0], [0, 0, 2, 0, 0], [-1, 2, 4, 2, -1], [0, 0, 2, 0, 0],
                    [0, 0, -1, 0, 0]]) / 8.0
#: R (B) at a G site whose row holds R (B): its same-colour neighbours left and right.
ROW = np.array([[0, 0, 0.5, 0, 0], [0, -1, 0, -1, 0], [-1, 4, 5, 4, -1], [0, -1, 0, -1, 0],
                [0, 0, 0.5, 0, 0]]) / 8.0
#: R at a B site (and B at an R site).
OPPOSITE = np.array([[0, 0, -1.5, 0, 0], [0, 2, 0, 2, 0], [-1.5, 0, 6, 0, -1.5],
                     [0, 2, 0, 2, 0], [0, 0, -1.5, 0, 0]]) / 8.0

#: Per site type of an RGGB mosaic, the kernels giving (R, G, B) there.
SITES = {
    "R": (_ID, G_AT_RB, OPPOSITE),
    "G in an R row": (ROW, _ID, ROW.T),
    "G in a B row": (ROW.T, _ID, ROW),
    "B": (OPPOSITE, G_AT_RB, _ID),
}
LUMINANCE = (0.2126, 0.7152, 0.0722)


def kernel(channel: str) -> np.ndarray:
    """The mean over the four site types of ``channel``'s kernel (``R``, ``G``, ``B``, ``Y``)."""
    out = np.zeros((5, 5))
    for ks in SITES.values():
        out += _site_kernel(ks, channel) / 4.0
    return out


def _site_kernel(ks, channel: str) -> np.ndarray:
    if channel == "Y":
        return sum(w * k for w, k in zip(LUMINANCE, ks, strict=True))
    return ks["RGB".index(channel)]


def response(channel: str, f: float, angle_deg: float) -> float:
    """The mean kernel's response at ``f`` cy/px along the normal of an edge turned
    ``angle_deg`` from the vertical (columns x, rows y; the kernels are symmetric)."""
    th = math.radians(angle_deg)
    dy, dx = np.mgrid[-2:3, -2:3]
    return float(np.sum(kernel(channel) * np.cos(
        2 * np.pi * f * (dx * math.cos(th) - dy * math.sin(th)))))


def noise_factor(channel: str) -> float:
    """A flat patch's standard deviation in ``channel`` over the per-site white noise's:
    ``sqrt(mean over site types of sum(k^2))`` (the G channel: sqrt(50/64); R and B:
    sqrt(252/256))."""
    return math.sqrt(np.mean([np.sum(_site_kernel(ks, channel) ** 2)
                              for ks in SITES.values()]))
