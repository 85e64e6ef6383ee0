"""netCDF-4 (HDF5) recordings in, read with h5py (``pip install imucal-nlp[netcdf]``) into the same
Recording the text loader builds.

Why h5py: a netCDF-4 file is an HDF5 file, and h5py reads it with one dependency (numpy) from a
wheel that bundles libhdf5; the netCDF4 package bundles the netCDF C library on top of that, and
xarray needs one of the two anyway. We read only what netCDF-4 puts in HDF5: datasets, their
attributes (``units``, ``sampling_rate``) and their dimension scales (CF's ``DIMENSION_LIST``).

Variables: ``data.columns`` maps a role to a variable's name (``ax: acceleration`` takes all three
axes of an (N, 3) variable; or ``ax``, ``ay``, ``az`` each a 1-D variable). Without a mapping a
role is the one variable whose ``units`` attribute is of its kind (acceleration, angular rate,
temperature); the time is the first dimension's coordinate (CF: ``units = "seconds since ..."``),
else the acceleration's ``sampling_rate`` attribute [Hz], else ``data.sample_rate``. Values are
converted from the file's units (UNITS): acceleration stays in its unit (m/s^2 or g, recorded as
data.unit), angular rate to rad/s or deg/s, temperature to degC, a magnetic field (read only when
mapped: ``mx: VARIABLE``) kept in uT, nT, gauss or milligauss (tesla to uT) as the magnetometer's unit
(mag.unit). Rows with a fill value (NaN) in a channel read are dropped: the stamps then skip, and
the time base keeps the gap (the spans are read as separate spans, imucal.data.timebase).
"""
from __future__ import annotations

import hashlib
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imucal.data.recording import MAX_ABS_VALUE, Recording
from imucal.data.timebase import rate_time_base, stamped_times
from imucal.errors import ImucalError, key_text, short
from imucal.files.inputs import max_data_bytes, open_regular
from imucal.data.unit_names import ACCELERATION_UNITS, FIELD_UNITS, KNOWN_UNITS, RATE_UNITS, TEMPERATURE_UNITS

if TYPE_CHECKING:
    from imucal.data.spec import DataSpec

#: File names read as netCDF-4/HDF5 (besides any file that starts with HDF5_SIGNATURE).
SUFFIXES = (".nc", ".nc4", ".h5", ".hdf5", ".he5", ".cdf")
#: The first bytes of an HDF5 file (HDF5 File Format Specification, "Format Signature").
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: The first bytes of a netCDF classic (version 1, 2 or 5) file, which h5py cannot read.
CLASSIC_SIGNATURE = b"CDF"
_INSTALL = "install the netCDF extra: pip install imucal-nlp[netcdf]"
_CONVERT = "convert it to netCDF-4 (nccopy -k nc4 IN OUT) or export the recording as CSV"

#: Attributes that describe a variable in words (CF's standard_name and long_name, and common others).
_DESCRIBING = ("standard_name", "long_name", "description", "full_name")
#: CF time units ("UNIT since DATE") -> factor to seconds.
TIME_SINCE = {"seconds": 1.0, "second": 1.0, "secs": 1.0, "sec": 1.0, "s": 1.0,
              "milliseconds": 1e-3, "millisecond": 1e-3, "msec": 1e-3, "ms": 1e-3,
              "microseconds": 1e-6, "microsecond": 1e-6, "us": 1e-6,
              "nanoseconds": 1e-9, "nanosecond": 1e-9, "ns": 1e-9,
              "minutes": 60.0, "minute": 60.0, "min": 60.0, "hours": 3600.0, "hour": 3600.0, "h": 3600.0,
              "days": 86400.0, "day": 86400.0, "d": 86400.0}
#: Options of text files that do not apply to a netCDF file (its variables name their units).
_TEXT_ONLY = ("delimiter", "skip_rows", "topic", "temp_topic", "gyro_path")


def is_netcdf(path: str | os.PathLike) -> bool:
    """A netCDF/HDF5 file: by its name (SUFFIXES) or by its first bytes (HDF5 or netCDF classic)."""
    p = Path(path)
    if p.suffix.lower() in SUFFIXES:
        return True
    try:
        if not os.path.isfile(p):
            return False
        with open(p, "rb") as f:  # 8 bytes of a regular file (open_regular checks it again before reading)
            head = f.read(len(HDF5_SIGNATURE))
    except OSError:
        return False
    return head == HDF5_SIGNATURE or (head[:3] == CLASSIC_SIGNATURE and head[3:4] in (b"\x01", b"\x02", b"\x05"))


@dataclass(frozen=True)
class _Channel:
    """One role's values (N,) or (N, 3) in our unit, and where they came from."""

    values: np.ndarray
    unit: str
    name: str  #: the variable(s), for messages


def _text(v: Any) -> str:
    """An HDF5 attribute as text (bytes, numpy strings and 1-element arrays)."""
    if isinstance(v, np.ndarray):
        v = v.ravel()[0] if v.size == 1 else v.tolist()
    if isinstance(v, (bytes, np.bytes_)):
        return bytes(v).decode("utf-8", "replace")
    return str(v)


def _units(var: Any) -> str | None:
    u = var.attrs.get("units")
    return None if u is None else _text(u).strip()


def _kind(units: str | None) -> str | None:
    """acceleration, angular rate or temperature, from a units attribute (None: none of them)."""
    if units is None:
        return None
    key = units.strip().lower()
    for kind, table in (("acceleration", ACCELERATION_UNITS), ("angular rate", RATE_UNITS),
                        ("temperature", TEMPERATURE_UNITS)):
        if key in table:
            return kind
    return None


def _datasets(f: Any) -> dict[str, Any]:
    """The file's numeric variables by name (netCDF-4 groups flattened to group/name)."""
    import h5py  # the optional extra (read_netcdf imported it already)

    out: dict[str, Any] = {}

    def visit(name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Dataset) and obj.dtype.kind in "fiu":
            out[name] = obj
    f.visititems(visit)
    return out


class _Reader:
    """The variables of one open file, read into channels with their units converted."""

    def __init__(self, f: Any, spec: DataSpec, path: Path) -> None:
        self.f, self.spec, self.path = f, spec, path
        self.vars = _datasets(f)

    def fail(self, what: str, field: str, fix: str) -> ImucalError:
        return ImucalError(what, file=str(self.path), field=field, fix=fix)

    def by_kind(self, kind: str, role: str) -> str | None:
        """The one variable whose units are of ``kind`` (None without one; two are refused)."""
        found = [n for n, v in self.vars.items() if _kind(_units(v)) == kind]
        if len(found) > 1:
            raise self.fail(f"variables {', '.join(found[:4])} all have {kind} units: which is {role}?",
                            f"data.columns.{role}", f"map it, e.g. columns: {{{role}: {found[0]}}}")
        return found[0] if found else None

    def variable(self, name: str, role: str) -> Any:
        if name not in self.vars:
            names = ", ".join(sorted(self.vars)[:12]) or "none"
            raise self.fail(f"no numeric variable {short(name)} (for {role}) in the file", f"data.columns.{role}",
                            f"map {role} to one of: {names}")
        return self.vars[name]

    def read(self, name: str, role: str) -> np.ndarray:
        var = self.variable(name, role)
        try:
            arr = np.asarray(var[()], dtype=float)
        except (OSError, ValueError, TypeError) as exc:  # a corrupt chunk or filter
            raise self.fail(f"cannot read variable {short(name)} ({' '.join(str(exc).split())[:120]})",
                            f"data.columns.{role}", "check that the file is complete (not cut or corrupt)") from None
        fill = var.attrs.get("_FillValue")
        if fill is not None:
            fv = np.asarray(fill, float).ravel()
            if fv.size == 1 and np.isfinite(fv[0]):
                arr = np.where(arr == fv[0], np.nan, arr)
        return arr

    def converted(self, name: str, role: str, kind: str, table: dict, default: tuple[str, float, float] | None
                  ) -> tuple[np.ndarray, str]:
        """The variable's values in our unit: its units attribute looked up in ``table``; ``default``
        when it has none (None: refused)."""
        units = _units(self.variable(name, role))
        if units is None:
            if default is None:
                raise self.fail(f"variable {short(name)} has no units attribute: its {kind} unit is unknown",
                                f"{name}.units", f"set it (e.g. ncatted -a units,{name},o,c,degC FILE)")
            conv = default
        else:
            conv = table.get(units.lower())
            if conv is None:
                raise self.fail(f"units {short(units)} of variable {short(name)} are not a unit of {kind} imucal "
                                f"knows ({KNOWN_UNITS[kind]})", f"{name}.units",
                                f"convert the variable to one of them, or map {role} to another variable")
        unit, k, off = conv
        return self.read(name, role) * k + off, unit

    def vector(self, prefix: str, kind: str, table: dict, default_unit: str) -> _Channel | None:
        """ax/ay/az (or gx/gy/gz): one (N, 3) variable, or three 1-D ones; None when absent."""
        roles = [f"{prefix}{a}" for a in "xyz"]
        cols = self.spec.columns
        given = [r for r in roles if r in cols]
        if given and any(not isinstance(cols[r], str) for r in given):
            raise self.fail("a netCDF variable is mapped by its name, not by a column index",
                            f"data.columns.{given[0]}", f"e.g. columns: {{{roles[0]}: VARIABLE}}")
        default = (default_unit, 1.0, 0.0)
        if given == [roles[0]] or not given:
            name = cols.get(roles[0]) or self.by_kind(kind, roles[0])
            if name is None:
                return None
            v, unit = self.converted(name, roles[0], kind, table, default)
            v = self.three_axes(v, name, roles[0])
            return _Channel(v, unit, name)
        if len(given) != 3:
            raise self.fail(f"only {', '.join(given)} of {', '.join(roles)} mapped", "data.columns",
                            f"map {roles[0]} to an (N, 3) variable, or all three to 1-D variables")
        parts = [self.converted(cols[r], r, kind, table, default) for r in roles]
        if len({u for _, u in parts}) != 1:
            raise self.fail(f"{', '.join(roles)} are in different units ({', '.join(u for _, u in parts)})",
                            "data.columns", "give the three axes in one unit")
        for (v, _), r in zip(parts, roles):
            if v.ndim != 1:
                raise self.fail(f"variable {short(cols[r])} has shape {v.shape}: {r} needs one value per sample",
                                f"data.columns.{r}", f"map {roles[0]} alone to an (N, 3) variable")
        if len({v.size for v, _ in parts}) != 1:
            raise self.fail(f"{', '.join(roles)} have different lengths ({', '.join(str(v.size) for v, _ in parts)})",
                            "data.columns", "map variables of one recording")
        return _Channel(np.column_stack([v for v, _ in parts]), parts[0][1], "/".join(cols[r] for r in roles))

    def three_axes(self, v: np.ndarray, name: str, role: str) -> np.ndarray:
        if v.ndim == 2 and v.shape[1] == 3:
            return v
        if v.ndim == 2 and v.shape[0] == 3 and v.shape[1] != 3:
            return v.T  # stored axis-major
        raise self.fail(f"variable {short(name)} has shape {v.shape}: {role} needs (N, 3), one row of three "
                        "axes per sample", f"data.columns.{role}", "map ax, ay and az to three 1-D variables instead")

    def lookalike(self, kind: str, role: str) -> None:
        """Refuse a 1-D variable named or described as ``kind`` whose units are not of that kind (or absent): left
        unread, a temperature sweep would silently get no temperature."""
        for name, var in self.vars.items():
            words = " ".join([name, *(_text(var.attrs[a]) for a in _DESCRIBING if a in var.attrs)]).lower()
            if var.ndim == 1 and kind[:4] in words and _kind(_units(var)) is None:
                units = _units(var)
                said = "has no units attribute" if units is None else f"has units {short(units)}"
                raise self.fail(f"variable {short(name)} looks like the {kind} ({role}) but {said}, and imucal reads "
                                f"{kind} only in {KNOWN_UNITS[kind]}: it would be left unread",
                                f"{name}.units", f"set its units to read it (ncatted -a units,{name},o,c,degC FILE)")

    def scalar(self, role: str, kind: str, table: dict) -> _Channel | None:
        name = self.spec.columns.get(role) or self.by_kind(kind, role)
        if name is None:
            self.lookalike(kind, role)
            return None
        if not isinstance(name, str):
            raise self.fail("a netCDF variable is mapped by its name, not by a column index", f"data.columns.{role}",
                            f"e.g. columns: {{{role}: VARIABLE}}")
        v, unit = self.converted(name, role, kind, table, None)
        if v.ndim != 1:
            raise self.fail(f"variable {short(name)} has shape {v.shape}: {role} needs one value per sample",
                            f"data.columns.{role}", "map a 1-D variable")
        return _Channel(v, unit, name)

    def field_variable(self) -> str:
        """An (N, 3) variable in a magnetic field unit, not mapped (a magnetometer is read only when mapped):
        its name and units, for the run to say it left it unread; "" without one."""
        for name, var in self.vars.items():
            units = _units(var)
            if units is not None and units.lower() in FIELD_UNITS and var.ndim == 2 and 3 in var.shape:
                return f"{key_text(name)} ({key_text(units)})"  # the file's text: one printable line
        return ""

    def time_variable(self, acc_name: str) -> str | None:
        """The time: data.columns.t, else the coordinate of the acceleration's first dimension."""
        if "t" in self.spec.columns:
            name = self.spec.columns["t"]
            self.variable(name, "t")
            return name
        var = self.vars.get(acc_name.split("/")[0])
        refs = var.attrs.get("DIMENSION_LIST") if var is not None else None
        if refs is not None and len(refs) and len(refs[0]):
            try:
                coord = self.f[refs[0][0]]
            except (ValueError, KeyError, TypeError, OSError):
                return None
            name = coord.name.lstrip("/")
            units = _units(coord)
            if name in self.vars and units is not None and " since " in units.lower():
                return name
        return None

    def time(self, name: str, n: int) -> tuple[np.ndarray, float]:
        """Stamps and their factor to seconds, from a CF ``units = "UNIT since DATE"``."""
        units = _units(self.variable(name, "t")) or ""
        m = re.match(r"\s*([A-Za-z]+)\s+since\s", units)
        factor = TIME_SINCE.get(m.group(1).lower()) if m else None
        if factor is None:
            raise self.fail(f"time variable {short(name)} has units {short(units or 'none')}: not \"UNIT since DATE\" "
                            f"with UNIT one of {', '.join(sorted(set(TIME_SINCE) - {'s', 'h', 'd'}))[:80]}...",
                            f"{name}.units", "give the time variable CF units, e.g. \"seconds since 2021-01-01\"")
        stamps = self.read(name, "t")
        if stamps.shape != (n,):
            raise self.fail(f"time variable {short(name)} has shape {stamps.shape}, the acceleration {n} samples",
                            "data.columns.t", "map the time coordinate of the acceleration's samples")
        return stamps, factor

    def rate(self, acc_name: str) -> float | None:
        """[Hz] the acceleration's sampling_rate attribute (in Hz), else data.sample_rate."""
        var = self.vars.get(acc_name.split("/")[0])
        if var is not None and "sampling_rate" in var.attrs:
            units = _text(var.attrs.get("sampling_rate_units", "Hz")).strip().lower()
            try:
                rate = float(np.asarray(var.attrs["sampling_rate"], float).ravel()[0])
            except (TypeError, ValueError, IndexError):
                rate = math.nan
            if units in ("hz", "1/s", "s-1") and math.isfinite(rate) and rate > 0:
                return rate
        return self.spec.sample_rate


def _check_spec(spec: DataSpec, path: Path) -> None:
    given = [n for n in _TEXT_ONLY if getattr(spec, n)]
    given += [n for n, v, d in (("format", spec.format, "auto"), ("time_unit", spec.time_unit, "auto"),
                                ("gyro_unit", spec.gyro_unit, "auto")) if v != d]
    if given:
        raise ImucalError(f"{given[0]} does not apply to a netCDF file", file=str(path), field=f"data.{given[0]}",
                          fix="drop it: the file's variables name their units")


def _sha256(f: Any) -> str:
    h = hashlib.sha256()
    for block in iter(lambda: f.read(1 << 20), b""):
        h.update(block)
    f.seek(0)
    return h.hexdigest()


def read_netcdf(spec: DataSpec, path: Path) -> Recording:
    """The Recording (imucal.data.recording.Recording) of a netCDF-4/HDF5 file (module docstring)."""
    _check_spec(spec, path)
    fd, _ = open_regular(path, field="data.path", max_bytes=max_data_bytes(),
                         fix="check the path (relative paths are relative to the YAML file)")
    with os.fdopen(fd, "rb") as fh:
        head = fh.read(len(HDF5_SIGNATURE))
        fh.seek(0)
        if head[:3] == CLASSIC_SIGNATURE:
            raise ImucalError("is a netCDF classic file, which h5py cannot read", file=str(path), field="data.path",
                              fix=_CONVERT)
        try:  # the optional extra: imported only when a netCDF file is read
            import h5py
        except ImportError:
            raise ImucalError("reading netCDF-4 files needs the h5py library", file=str(path), field="data.path",
                              fix=_INSTALL) from None
        sha = _sha256(fh)
        try:
            f = h5py.File(fh, "r")
        except (OSError, ValueError) as exc:  # truncated, corrupt, or not HDF5 at all
            text = " ".join(str(exc).split())[:160]
            raise ImucalError(f"is not a readable netCDF-4/HDF5 file ({text})", file=str(path), field="data.path",
                              fix="check that the file is complete (not cut or corrupt), or " + _CONVERT) from None
        try:
            with f:
                return _recording(_Reader(f, spec, path), spec, path, sha)
        except ImucalError:
            raise
        except Exception as exc:  # h5py raises many types on a damaged file (OSError, KeyError, RuntimeError ...)
            text = " ".join(str(exc).split())[:160] or type(exc).__name__
            raise ImucalError(f"cannot read the netCDF-4/HDF5 file ({type(exc).__name__}: {text})", file=str(path),
                              field="data.path", fix="check that the file is complete (not cut or corrupt)") from None


def _recording(rd: _Reader, spec: DataSpec, path: Path, sha: str) -> Recording:
    acc = rd.vector("a", "acceleration", ACCELERATION_UNITS, spec.unit)
    if acc is None:
        raise rd.fail("no variable with acceleration units (" + ", ".join(sorted(ACCELERATION_UNITS)[:6]) + " ...)",
                      "data.columns.ax", "map ax to the acceleration variable (data.columns)")
    if spec.unit not in ("raw", acc.unit):
        raise rd.fail(f"data.unit {short(spec.unit)} disagrees with the file's {acc.unit} for {acc.name}",
                      "data.unit", "drop data.unit: the variable's units attribute gives it")
    n = acc.values.shape[0]
    gyro = rd.vector("g", "angular rate", RATE_UNITS, "raw")
    temp = rd.scalar("temp", "temperature", TEMPERATURE_UNITS)
    # a magnetometer only when mapped (data.columns mx: VARIABLE): a field variable is read, not guessed
    mag = rd.vector("m", "magnetic field", FIELD_UNITS, "raw") if {"mx", "my", "mz"} & set(spec.columns) else None
    for ch, role in ((gyro, "gx"), (temp, "temp"), (mag, "mx")):
        if ch is not None and ch.values.shape[0] != n:
            raise rd.fail(f"variable {short(ch.name)} has {ch.values.shape[0]} samples, the acceleration {n}",
                          f"data.columns.{role}", "map variables of one recording (one time dimension)")
    tname = rd.time_variable(acc.name)
    stamps, factor = rd.time(tname, n) if tname is not None else (None, 1.0)
    keep = np.isfinite(acc.values).all(axis=1)
    for ch in (gyro, temp, mag):
        if ch is not None:
            keep &= np.isfinite(ch.values).all(axis=1) if ch.values.ndim == 2 else np.isfinite(ch.values)
    if stamps is not None:
        keep &= np.isfinite(stamps)
    idx = np.flatnonzero(keep)  # rows with a fill value are dropped: a gap in the stamps
    if idx.size == 0:
        if n == 0:
            raise rd.fail(f"variable {short(acc.name)} holds no samples", "data.columns.ax", "record samples")
        empty = [ch.name for ch in (acc, gyro, temp, mag) if ch is not None and not np.isfinite(ch.values).any()]
        raise rd.fail("has no rows with every channel read present (all fill values"
                      + (f": {short(empty[0])} holds no value)" if empty else ")"), "data",
                      "record samples, or map variables that hold them")
    raw = acc.values[idx]
    g = None if gyro is None else gyro.values[idx]
    m = None if mag is None else mag.values[idx]
    for ch, arr in ((acc, raw), (gyro, g), (mag, m)):
        if arr is not None and not (np.abs(arr) <= MAX_ABS_VALUE).all():
            k = int(idx[np.flatnonzero((np.abs(arr) > MAX_ABS_VALUE).any(axis=1))[0]])
            raise rd.fail(f"sample {k} of {short(ch.name)} holds a value beyond +-{MAX_ABS_VALUE:g} (corrupt)", "data",
                          "remove or repair the corrupt samples before calibrating")
    if stamps is not None:
        s = stamps[idx] * factor
        d = np.diff(s)
        if (d <= 0).any():
            k = int(idx[np.flatnonzero(d <= 0)[0] + 1])
            raise rd.fail(f"time is not strictly increasing at sample {k}", f"data.columns.t",
                          "sort the samples by time and drop duplicates")
        t, unit, note, tb = stamped_times(s - s[0], "s", spec.sample_rate, tname, path)
        note = f"{tname} ({_units(rd.vars[tname])}) [s]; " + note if note else f"{tname} [s]"
        t_source = s
    else:
        rate = rd.rate(acc.name)
        if rate is None:
            raise rd.fail("no time variable and no sampling rate", "data.sample_rate",
                          "map data.columns.t to the time variable, or give data.sample_rate in Hz")
        t_source, tname = None, "t"
        if idx.size == n:
            unit, note, tb = rate_time_base(rate)
            t = idx / float(rate)
        else:  # dropped rows leave their steps out: the time base names the gaps
            t, unit, note, tb = stamped_times(idx / float(rate), "s", None, "sample index / sampling_rate", path)
            note = f"no time variable: {rate:g} Hz, rows with fill values left out as gaps; " + note
    return Recording(t=t, raw=raw, temp=None if temp is None else temp.values[idx], unit=acc.unit,
                     source=str(path), sha256=sha, gyro=g, t_source=t_source, time_unit="s", time_note=note,
                     time_column=tname, gyro_unit="raw" if gyro is None else gyro.unit, time_base=tb, mag=m,
                     mag_unit="raw" if mag is None else mag.unit,
                     mag_unread="" if mag is not None else rd.field_variable())
