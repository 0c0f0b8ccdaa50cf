"""Compare JSON documents the way their numbers can be reproduced on another machine.

A number recomputed from the same inputs by the same code differs between CPUs in its last
bits (OpenBLAS picks its kernels by the instruction set, and they sum in another order: on an
AVX-512 processor a Moore-Penrose fit moves by ~1e-13 relative, a ΔE of 1e-13 becomes
1.1e-12) and an iterative solution by its own tolerance (Brent's bounded minimisation stops
within sqrt(eps) ≈ 1.5e-8 relative of the minimum). :data:`REL_TOL` and :data:`ABS_TOL` lie above both and far below any printed digit.
"""

from __future__ import annotations

import math
from typing import Any

#: Relative tolerance of a number: 67 times Brent's sqrt(eps), 1e-6 of a printed 4-digit value.
REL_TOL = 1e-6
#: Absolute tolerance near zero (a ΔE of a patch fitted exactly is 1e-13 on one CPU, 1e-12 on
#: another).
ABS_TOL = 1e-9


def differences(a: Any, b: Any, where: str = "$", *, rel_tol: float = REL_TOL,
                abs_tol: float = ABS_TOL) -> list[str]:
    """Where the JSON values ``a`` (recorded) and ``b`` (now) differ: keys, lengths, strings
    and booleans exactly, numbers to ``rel_tol`` relative or ``abs_tol`` absolute (NaN equals
    NaN)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{where}.{k}: only in the recorded document" for k in a.keys() - b.keys()]
        out += [f"{where}.{k}: not in the recorded document" for k in b.keys() - a.keys()]
        for k in a.keys() & b.keys():
            out += differences(a[k], b[k], f"{where}.{k}", rel_tol=rel_tol, abs_tol=abs_tol)
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{where}: {len(a)} items recorded, {len(b)} now"]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in differences(x, y, f"{where}[{i}]", rel_tol=rel_tol, abs_tol=abs_tol)]
    if is_number(a) and is_number(b):
        if math.isclose(a, b, rel_tol=rel_tol, abs_tol=abs_tol) or (a != a and b != b):
            return []
    elif isinstance(a, bool) or isinstance(b, bool):
        if a is b:
            return []
    elif a == b:
        return []
    return [f"{where}: recorded {a!r}, now {b!r}"]


def is_number(value: Any) -> bool:
    """An int or float and not a bool (JSON's true and false stay exact)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)
