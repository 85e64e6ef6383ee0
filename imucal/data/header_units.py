"""What a text file's head says besides its columns' roles: the units its names state (acc_x [g]), a line of
units under the names, and a sample rate on a metadata line above the header (Fs,100); the spec they fill.

imucal.data.layout finds the header and calls these; the readers (imucal.data.whole, imucal.data.stream) read
with the spec that header_spec (imucal.data.layout) returns.
"""
from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

from imucal.data.header_names import TEXT_UNITS, implied_unit, is_celsius, is_unit_name, read_name, sensor_unit
from imucal.data.lines import is_number, split
from imucal.data.recording import MAX_RATE_HZ, MIN_RATE_HZ
from imucal.data.spec import DataSpec
from imucal.data.timebase import RATE_TOLERANCE
from imucal.errors import ImucalError, short

#: Keys of a metadata line above the header that states the sample rate [Hz] ("Fs,100": the MPU-6050
#: logger of tomisuarez's calibration; "sample_rate: 200 Hz").
RATE_KEYS = ("fs", "sample rate", "sample_rate", "sampling rate", "sampling_rate", "sampling frequency",
             "sample frequency", "rate", "frequency", "odr", "data rate")


def metadata_rate(meta: list[str], delim: str | None) -> float | None:
    """The sample rate [Hz] one metadata line states as key and value (a "Hz" after it allowed); None when
    no line does, or two disagree."""
    found = set()
    for ln in meta:
        parts = [p.strip().strip("\"'") for p in re.split(r"[,;:=\t]", ln.strip().lstrip("#"), maxsplit=1)]
        if len(parts) == 2 and parts[0].lower().removesuffix(" [hz]").removesuffix(" (hz)") in RATE_KEYS:
            value = parts[1].removesuffix("Hz").removesuffix("hz").strip().rstrip(",;")
            if is_number(value) and 0 < float(value) < float("inf"):
                found.add(float(value))
    return found.pop() if len(found) == 1 else None


def units_row(line: str, delim: str | None, n: int) -> list[str] | None:
    """The units of a line under the header that holds one per column (some empty) and no number, at least
    one a unit imucal knows; None for any other line."""
    toks = [t.strip().strip("\"'").strip("[]()").strip() for t in split(line, delim)]
    if len(toks) != n or any(is_number(t) for t in toks if t) or any(len(t) > 16 for t in toks):
        return None
    return toks if any(t and is_unit_name(t) for t in toks) else None


#: The spec's field each sensor's stated unit fills, its value when not given, and the roles that state it
#: (the magnetometer's: the Recording's mag_unit, which the run's mag.unit is checked against).
_UNIT_FIELDS = (("unit", "raw", ("ax", "ay", "az")), ("gyro_unit", "auto", ("gx", "gy", "gz")))
_MAG_FIELD = ("mag_unit", "raw", ("mx", "my", "mz"))  # named data.columns.mx in messages: the spec has no field
_EXAMPLE = {"a": "m/s^2", "g": "rad/s", "m": "uT"}


def stated_units(names: list[str], cols: dict[str, int], path: Path) -> dict[str, str]:
    """The acceleration's and the rate's units the header's names state (the three axes agreeing); a
    temperature stated in another unit than degC, or a unit not known, is refused naming the column."""
    out: dict[str, str] = {}
    if "temp" in cols:
        u = read_name(names[cols["temp"]]).unit
        if u is not None and not is_celsius(u):
            raise ImucalError(f"the temperature column {short(names[cols['temp']])} states {short(u)}: imucal reads "
                              "degrees Celsius", file=str(path), field="data.columns.temp",
                              fix="convert the column to degC (and name it e.g. temp [degC])")
    for spec_field, _, roles in (*_UNIT_FIELDS, _MAG_FIELD):
        stated = {}
        for r in (r for r in roles if r in cols):
            name = read_name(names[cols[r]])
            if (u := name.unit or implied_unit(names[cols[r]], names)) is not None:
                kind = name.role or r  # its name's sensor (a gyro-only file's axes: gx..)
                unit = sensor_unit(kind, u)
                if unit is None:
                    raise ImucalError(f"column {short(names[cols[r]])} states {short(u)}, where a text file's "
                                      f"{kind[0]}x, {kind[0]}y, {kind[0]}z are read in {TEXT_UNITS[kind[0]]}",
                                      file=str(path), field=f"data.columns.{r}",
                                      fix=f"write the column in one of those units and name it so, e.g. {kind} "
                                          f"[{_EXAMPLE[kind[0]]}]")
                stated[names[cols[r]]] = unit
        if len(set(stated.values())) > 1:
            (n1, u1), *rest = stated.items()
            n2, u2 = next((n, u) for n, u in rest if u != u1)
            raise ImucalError(f"columns {short(n1)} and {short(n2)} state different units ({u1}, {u2})",
                              file=str(path), field="data.columns.mx" if spec_field == "mag_unit" else f"data.{spec_field}",
                              fix="give every axis in one unit")
        if stated:
            out[spec_field] = next(iter(stated.values()))
    return out


def spec_with_units(spec: DataSpec, units: dict, sample_rate: float | None, timed: bool, path: Path) -> DataSpec:
    """``spec`` with the ``units`` a header states where it gave none (data.unit raw, data.gyro_unit auto) and the
    ``sample_rate`` a line above it states for a file without a time column (not ``timed``); a unit or a rate
    given that disagrees with the file's is refused, naming both."""
    given = {}
    if sample_rate is not None and (spec.sample_rate is not None or not timed) and not (
            MIN_RATE_HZ <= sample_rate <= MAX_RATE_HZ):  # the file's line is named, not data.sample_rate's value
        raise ImucalError(f"the line above its header states a sample rate of {sample_rate:g} Hz: not an IMU rate",
                          file=str(path), field="data.sample_rate",
                          fix=f"correct the line to the logging rate in Hz ({MIN_RATE_HZ:g} to {MAX_RATE_HZ:g})")
    if sample_rate is not None and spec.sample_rate is None and not timed:
        given["sample_rate"] = sample_rate  # "Fs,100" above the header of a file without a time column
    elif sample_rate is not None and spec.sample_rate is not None and (
            abs(spec.sample_rate / sample_rate - 1.0) > RATE_TOLERANCE):
        raise ImucalError(f"sample rate {spec.sample_rate:g} Hz given, but the file states {sample_rate:g} Hz "
                          "above its header: two sources of time disagree", file=str(path), field="data.sample_rate",
                          fix=f"give {sample_rate:g} (or leave the rate out), or correct the file's line")
    for spec_field, default, _ in _UNIT_FIELDS:
        stated, now = units.get(spec_field), getattr(spec, spec_field)
        if stated is None or stated == now or (stated == "raw" and now in ("raw", "counts")):
            continue
        if now != default and not (now == "counts" and stated == "raw"):
            raise ImucalError(f"data.{spec_field} {short(now)} given, but the header states {stated}",
                              file=str(path), field=f"data.{spec_field}",
                              fix=f"give {stated} (or leave the unit out), or correct the header")
        given[spec_field] = stated
    return replace(spec, **given) if given else spec
