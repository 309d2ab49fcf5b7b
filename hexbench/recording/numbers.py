"""Number handling shared by the recordings: binary quantisation and fast JSON number text.

Quantising to a multiple of 2^-bits leaves the low mantissa bits zero, which is exact in
float64 (the decoded value is exactly the stored one) and lets zstd compress the logged
signals to a fraction of their float64 size. JSON arrays are written with 3 decimals (1 mrad for angles) through
a lookup table of pre-formatted numbers (vectorised; a `%` format per number would cost more
than the whole recording budget).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

JSON_DECIMALS = 3
_LUT_MAX = 16_000  # table covers |x| <= 16.0 at 3 decimals; larger values are formatted one by one


def quantize(x: np.ndarray, bits: int) -> np.ndarray:
    """Round to the nearest multiple of 2^-bits (exact in float64)."""
    scale = float(2 ** bits)
    return np.round(np.asarray(x, dtype=np.float64) * scale) / scale


def _fixed_text(i: int) -> str:
    s = f"{i / 10 ** JSON_DECIMALS:.{JSON_DECIMALS}f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


@lru_cache(maxsize=1)
def _lut() -> np.ndarray:
    return np.array([_fixed_text(i) for i in range(-_LUT_MAX, _LUT_MAX + 1)], dtype=object)


def json_number_cells(x: np.ndarray) -> np.ndarray:
    """(n, m) floats -> (n, m) object array of JSON number text, each rounded to JSON_DECIMALS decimals."""
    x = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise ValueError("cannot log NaN or infinite values")
    ints = np.rint(x * 10 ** JSON_DECIMALS).astype(np.int64)
    inside = np.abs(ints) <= _LUT_MAX
    text = _lut()[np.where(inside, ints, 0) + _LUT_MAX]
    if not inside.all():
        text[~inside] = [_fixed_text(int(i)) for i in ints[~inside]]
    return text


def json_bool_cells(x: np.ndarray) -> np.ndarray:
    """(n, m) bools -> (n, m) object array of 'true' / 'false'."""
    return np.array(["false", "true"], dtype=object)[np.asarray(x, dtype=np.int64)]
