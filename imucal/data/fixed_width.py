"""Rows of fixed-width numbers (MATLAB's ``save -ascii``, imu_tk's .mat files: ``%16.7e`` in every
column of every line) parsed as digits in columns, every number at once, to the same doubles numpy's
text reader gives.

Every line has the same length and every column of bytes one role in every line: a separator
(spaces), a sign (space, "-" or "+"), digits, the decimal point, the exponent's "e" and its sign.
A number is then its digits as an integer M (at most 2^53, exact in a double) and a power of ten
10^E with |E| <= 22 (exact too), and M * 10^E, or M / 10^-E, is one rounding of the exact value:
the correctly rounded double a decimal reader returns (Clinger's fast path, W. D. Clinger, "How to
read floating point numbers accurately", PLDI 1990). Any other text (variable widths, tabs, CR,
comments, more digits, larger exponents) is left to numpy's reader: ``table`` returns None.
"""
from __future__ import annotations

import numpy as np

#: Exact powers of ten in a double: 10^0 .. 10^22.
_POW10 = np.array([10.0**k for k in range(23)])
_SPACE, _MINUS, _PLUS, _POINT, _ZERO, _NINE = (ord(c) for c in " -+.09")


def _columns(lo: np.ndarray, hi: np.ndarray, rows: np.ndarray) -> list[str] | None:
    """The role of each byte column from its least and greatest byte: " " space, "d" digit, "." point,
    "e" exponent mark, "s" sign or space, "x" exponent sign; None when a column has no single role."""
    roles = []
    for c, (a, b) in enumerate(zip(lo.tolist(), hi.tolist())):
        if a == b == _SPACE:
            roles.append(" ")
        elif _ZERO <= a and b <= _NINE:
            roles.append("d")
        elif a == b == _POINT:
            roles.append(".")
        elif a == b and chr(a) in "eE":
            roles.append("e")
        elif a >= _PLUS and b <= _MINUS and not (rows[:, c] == ord(",")).any():
            roles.append("x")  # "+" or "-" in every line: an exponent's sign (a mantissa's, if it leads)
        elif a >= _SPACE and b <= _MINUS and np.isin(rows[:, c], (_SPACE, _PLUS, _MINUS)).all():
            roles.append("s")
        else:
            return None
    return roles


def _fields(roles: list[str]) -> list[tuple[int | None, list[int], int, int | None, list[int]]] | None:
    """Each number's columns: (sign, mantissa digits, digits after the point, exponent sign, exponent
    digits), read from the roles left to right (sign? digits+ (. digits*)? (e sign? digits+)?, numbers
    apart by a space column); None for any other sequence."""
    out, c, n = [], 0, len(roles)
    while c < n:
        if roles[c] == " ":
            c += 1
            continue
        if out and roles[c - 1] != " ":
            return None  # two numbers touching
        sign = c if roles[c] in "sx" else None
        c += sign is not None
        digits, frac = [], 0
        while c < n and roles[c] == "d":
            digits.append(c)
            c += 1
        if not digits:
            return None
        if c < n and roles[c] == ".":
            c += 1
            while c < n and roles[c] == "d":
                digits.append(c)
                frac += 1
                c += 1
        esign, edigits = None, []
        if c < n and roles[c] == "e":
            c += 1
            if c < n and roles[c] == "x":
                esign, c = c, c + 1
            while c < n and roles[c] == "d":
                edigits.append(c)
                c += 1
            if not edigits:
                return None
        if c < n and roles[c] != " ":
            return None
        out.append((sign, digits, frac, esign, edigits))
    return out


def _digits(rows: np.ndarray, cols: list[int]) -> np.ndarray:
    """The integer the digit columns ``cols`` spell in each line (int64; at most 18 digits)."""
    v = np.zeros(rows.shape[0], np.int64)
    for c in cols:
        v *= 10
        v += rows[:, c]
        v -= _ZERO
    return v


def table(blob: bytes, start: int, usecols: list[int]) -> np.ndarray | None:
    """The (lines, len(usecols)) doubles of the lines of ``blob`` from offset ``start`` on (each ended by
    "\\n"), columns ``usecols`` of the numbers of a line, as numpy's reader gives them (its whitespace
    delimiter); None when the text is not fixed-width numbers the fast path reads exactly."""
    width = blob.find(b"\n", start) + 1 - start
    if width < 2 or (len(blob) - start) % width or b"\r" in blob or b"\t" in blob:
        return None
    rows = np.frombuffer(blob, np.uint8, offset=start).reshape(-1, width)
    if not (rows[:, -1] == ord("\n")).all():
        return None
    rows = rows[:, :-1]
    roles = _columns(rows.min(axis=0), rows.max(axis=0), rows)
    fields = None if roles is None else _fields(roles)
    if fields is None or max(usecols) >= len(fields):
        return None
    out = np.empty((rows.shape[0], len(usecols)))
    for k, j in enumerate(usecols):
        sign, digits, frac, esign, edigits = fields[j]
        if len(digits) > 18 or len(edigits) > 3:
            return None
        m = _digits(rows, digits)
        if m.max(initial=0) > 2**53:
            return None
        e = _digits(rows, edigits) if edigits else np.zeros(rows.shape[0], np.int64)
        if esign is not None:
            e = np.where(rows[:, esign] == _MINUS, -e, e)
        e -= frac
        if np.abs(e).max(initial=0) > 22:
            return None
        p = _POW10[np.abs(e)]
        mf = m.astype(float)  # exact: m <= 2^53
        v = np.where(e >= 0, mf * p, mf / p)  # one rounding of the exact value
        if sign is not None:
            v = np.where(rows[:, sign] == _MINUS, -v, v)
        out[:, k] = v
    return out
