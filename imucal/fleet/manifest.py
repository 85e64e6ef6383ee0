"""The fleet manifest: which units to calibrate, with which settings, against which tolerances.

Three forms (docs/fleet.md):

* YAML::

      format: imucal-fleet-manifest      # optional; format_version: 1
      config: run.yaml                   # optional: an `imucal calibrate` run file (its data.path is not used)
      settings: {fit: {mode: means}}     # optional: run-file sections, merged over `config`
      tolerances: {bias_abs_max: 0.5, angle_deg_from_90_max: 0.5, rms_max: 0.01}
      units:                             # a list, the name of a CSV listing them, or `folder:` instead
        - {id: U0001, data: U0001.csv, gyro_data: U0001_gyro.csv, settings: {gravity: {value: 9.81}}}

* CSV with a header: ``unit,data[,gyro_data]`` and optional per-unit override columns named by
  their run-file key (``gravity.value``, ``fit.mode``); an empty cell overrides nothing.
* a folder: every ``*.csv`` in it is one unit, named by its file stem.

Relative paths are relative to the manifest's folder. Each unit's settings are the shared
settings with its overrides merged in, validated as a run file (imucal.config.run), so a unit
is calibrated exactly as ``imucal calibrate`` would calibrate it.
"""
from __future__ import annotations

import copy
import csv
import hashlib
import os
import io
import json
import re
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Literal, Mapping

import yaml

from imucal import __version__
from imucal.config.limits import MAX_FLEET_UNITS
from imucal.config.run import RunConfig, config_from_dict
from imucal.errors import ImucalError, key_text, short
from imucal.files.inputs import read_input_text, resolve
from imucal.files.schema import fill, keys, rule
from imucal.files.yamlio import check_structure, parse_scalar, read_yaml

FORMAT = "imucal-fleet-manifest"
FORMAT_VERSION = 1
#: A unit id names its output folder: letters, digits, '.', '_', '-', starting with a letter or digit.
UNIT_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}\Z")
#: Names the fleet report takes in DIR (imucal.fleet.report): no unit folder may take them.
REPORT_NAMES = re.compile(r"(fleet(\.(csv|txt|parquet)|_.*\.png)|report\.html)\Z", re.IGNORECASE)
#: The keys of each run-file section, from RunConfig itself (a new section needs no line here); a CSV
#: override column is checked against them even when all its cells are empty.
SECTION_KEYS = {name: tuple(keys(tp)) for name, tp in keys(RunConfig).items()}
#: Run-file sections a manifest may set (output.dir is the batch's --out DIR/<unit>).
SECTIONS = tuple(SECTION_KEYS)
#: Keys that name files: given per unit (data, gyro_data), never as shared settings.
FILE_KEYS = ("path", "gyro_path")


_TOLERANCE = rule(ge=0, msg="{value} must be a non-negative number",
                  fix="e.g. tolerances: {bias_abs_max: 0.5, angle_deg_from_90_max: 0.5, rms_max: 0.01} "
                      "(m/s^2 and degrees)")


@dataclass(frozen=True)
class Tolerances:
    """Pass/fail limits of one unit; None: not checked.

    ``bias_abs_max`` [m/s^2]: |s_i / b_i|, the zero-g reading of each axis in m/s^2.
    ``angle_deg_from_90_max`` [deg]: |angle - 90 deg| of phi, psi and theta.
    ``rms_max`` [m/s^2]: RMS of |a| - g over the static interval means.
    ``scale_min``, ``scale_max`` [raw per m/s^2]: range of each scale b_i.
    """

    bias_abs_max: float | None = field(default=None, metadata=_TOLERANCE)
    angle_deg_from_90_max: float | None = field(default=None, metadata=_TOLERANCE)
    rms_max: float | None = field(default=None, metadata=_TOLERANCE)
    scale_min: float | None = field(default=None, metadata=_TOLERANCE)
    scale_max: float | None = field(default=None, metadata=_TOLERANCE)

    def __post_init__(self) -> None:
        if self.scale_min is not None and self.scale_max is not None and self.scale_min > self.scale_max:
            raise ImucalError(f"scale_min {self.scale_min:g} is above scale_max {self.scale_max:g}",
                              field="tolerances.scale_min", fix="give scale_min below scale_max (or swap them)")

    def given(self) -> dict[str, float]:
        return {f.name: float(getattr(self, f.name)) for f in fields(self) if getattr(self, f.name) is not None}


@dataclass(frozen=True)
class Unit:
    """One unit of the fleet: its id, the run config it is calibrated with, and the settings hash."""

    id: str
    config: RunConfig  #: data.path (and data.gyro_path) absolute; source None, as `imucal calibrate --data`
    settings_hash: str  #: SHA-256 of the unit's settings (without file names) and the imucal version

    @property
    def inputs(self) -> dict[str, str]:
        """Role -> path of the unit's input files."""
        d = {"data": self.config.data.path}
        if self.config.data.gyro_path is not None:
            d["gyro_data"] = self.config.data.gyro_path
        return d


@dataclass(frozen=True)
class Manifest:
    source: str
    units: tuple[Unit, ...]
    tolerances: Tolerances


def check_unit_id(uid: Any, path: str, where: str) -> str:
    if not isinstance(uid, str) or not UNIT_ID.match(uid):
        raise ImucalError(f"unit id {short(uid)} is not a safe folder name", file=path, field=where,
                          fix="use 1 to 64 letters, digits, '.', '_' or '-', starting with a letter or digit")
    if REPORT_NAMES.match(uid):
        raise ImucalError(f"unit id {short(uid)} is the name of a fleet report file", file=path, field=where,
                          fix="give the unit another id")
    return uid


def _merge(base: dict, over: Mapping) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, Mapping) and isinstance(out.get(k), Mapping) else copy.deepcopy(v)
    return out


def _settings(raw: Any, path: str, where: str) -> dict:
    """Run-file sections without file names; refuses anything else in one line."""
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        raise ImucalError(f"must be a mapping of run-file sections, got {type(raw).__name__}", file=path, field=where,
                          fix=f"sections: {', '.join(SECTIONS)}")
    for k, v in raw.items():
        if k not in SECTIONS:
            raise ImucalError(f"unknown section {short(k)}", file=path, field=f"{where}.{key_text(k)}",
                              fix=f"allowed sections: {', '.join(SECTIONS)}")
        if k == "data" and isinstance(v, Mapping):
            for fk in FILE_KEYS:
                if fk in v:
                    raise ImucalError("files are named per unit", file=path, field=f"{where}.data.{fk}",
                                      fix="give each unit's data (and gyro_data) in units:")
    return copy.deepcopy(dict(raw))


def _settings_hash(settings: Mapping) -> str:
    blob = json.dumps({"settings": settings, "imucal": __version__}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()


def _unit(uid: str, data: Any, gyro: Any, over: dict, shared: dict, base: Path, path: str, where: str) -> Unit:
    files = {}
    for role, v in (("path", data), ("gyro_path", gyro)):
        if v is None or v == "":
            continue
        if not isinstance(v, str) or "\x00" in v or len(v) > 4000:
            raise ImucalError(f"{short(v)} is not a file name", file=path,
                              field=f"{where}.{'data' if role == 'path' else 'gyro_data'}",
                              fix="give the recording's path as text, relative to the manifest")
        files[role] = (str(resolve(base / v, field=f"{where}.{'data' if role == 'path' else 'gyro_data'}"))
                       if not Path(v).is_absolute() else v)
    if "path" not in files:
        raise ImucalError("no data file", file=path, field=f"{where}.data", fix="give the unit's recording")
    settings = _merge(shared, over)
    if isinstance(settings.get("output"), Mapping):  # the batch writes to DIR/<unit id>
        settings["output"] = {k: v for k, v in settings["output"].items() if k != "dir"}
    full = _merge(settings, {"data": files})
    try:
        cfg = config_from_dict(full, path)
    except ImucalError as exc:
        raise ImucalError(exc.message, file=path, field=f"{where}: {exc.field}", fix=exc.fix) from None
    return Unit(id=uid, config=replace(cfg, source=None), settings_hash=_settings_hash(settings))


def _csv_units(text: str, path: str) -> list[tuple[str, Any, Any, dict, str]]:
    """(id, data, gyro_data, overrides, where) of each row of a CSV listing."""
    rows = list(csv.reader(io.StringIO(text)))
    rows = [r for r in rows if r and any(c.strip() for c in r)]
    if not rows:
        raise ImucalError("no header and no units", file=path, field="header", fix="first line: unit,data[,gyro_data]")
    head = [h.strip() for h in rows[0]]
    if "unit" not in head or "data" not in head:
        raise ImucalError(f"header {short(','.join(head))} lacks unit and data", file=path, field="header",
                          fix="first line: unit,data[,gyro_data][,override columns such as gravity.value]")
    if len(set(head)) != len(head):
        raise ImucalError("a column is named twice", file=path, field="header", fix="name each column once")
    for h in head:
        sec, _, key = h.partition(".")
        if h not in ("unit", "data", "gyro_data") and (sec not in SECTION_KEYS or key in FILE_KEYS
                                                       or key not in SECTION_KEYS[sec]):
            raise ImucalError(f"unknown column {short(h)}", file=path, field="header",
                              fix="unit, data, gyro_data, or a run-file key such as gravity.value or fit.mode")
    out = []
    for n, r in enumerate(rows[1:], start=2):
        if len(r) != len(head):
            raise ImucalError(f"{len(r)} cells, the header has {len(head)}", file=path, field=f"line {n}",
                              fix="one cell per column (empty for none)")
        cells = dict(zip(head, (c.strip() for c in r)))
        over: dict = {}
        for h, c in cells.items():
            if "." in h and c != "":
                sec, key = h.split(".")
                try:
                    val = parse_scalar(c)  # as read_yaml reads numbers: 9:48 stays text
                except yaml.YAMLError:
                    val = c
                over.setdefault(sec, {})[key] = val
        out.append((cells["unit"], cells["data"], cells.get("gyro_data") or None, over, f"line {n}"))
    return out


def _collect(listing: list[tuple[str, Any, Any, dict, str]], shared: dict, base: Path, path: str) -> tuple[Unit, ...]:
    if len(listing) > MAX_FLEET_UNITS:
        raise ImucalError(f"{len(listing)} units, above the limit of {MAX_FLEET_UNITS}", file=path, field="units",
                          fix="split the fleet into several manifests")
    if not listing:
        raise ImucalError("no units", file=path, field="units", fix="list at least one unit")
    units, seen = [], {}
    for uid, data, gyro, over, where in listing:
        check_unit_id(uid, path, f"{where}.id")
        if uid.lower() in seen:  # folders of ids that differ only in case collide on some file systems
            raise ImucalError(f"unit id {short(uid)} is given twice ({seen[uid.lower()]})", file=path,
                              field=f"{where}.id", fix="give each unit its own id")
        seen[uid.lower()] = where
        units.append(_unit(uid, data, gyro, over, shared, base, path, where))
    return tuple(units)


def _folder_units(folder: Path, pattern: str, path: str, where: str) -> list[tuple[str, Any, Any, dict, str]]:
    if not folder.is_dir():
        raise ImucalError("is not a folder", file=str(folder), field=where, fix="give the folder of recordings")
    files = sorted(p for p in folder.glob(pattern) if p.is_file())
    return [(p.stem, str(p), None, {}, f"{where} {p.name}") for p in files]


def load_manifest(path: str | Path, config: str | Path | None = None) -> Manifest:
    """Read a YAML or CSV manifest, or a folder of recordings; ``config`` gives shared settings
    (an `imucal calibrate` run file) to a CSV or folder, or to a YAML manifest without one."""
    p = Path(path)
    src = str(p)
    shared = _run_file_settings(config) if config is not None else {}
    if os.path.isdir(p):  # False, not OSError, for a name too long
        units = _collect(_folder_units(p, "*.csv", src, "folder"), shared, p, src)
        return Manifest(source=src, units=units, tolerances=Tolerances())
    if p.suffix.lower() == ".csv":
        text = read_input_text(p, field="manifest", fix="give a YAML or CSV manifest, or a folder")
        return Manifest(source=src, units=_collect(_csv_units(text, src), shared, p.parent, src),
                        tolerances=Tolerances())
    d = read_yaml(p, "manifest", "give a YAML or CSV manifest, or a folder (see docs/fleet.md)")
    return manifest_from_dict(d, src, shared if config is not None else None)


def _run_file_settings(config: str | Path) -> dict:
    d = read_yaml(config, "config", "pass an `imucal calibrate` run file")
    if not isinstance(d, Mapping):
        raise ImucalError(f"top level must be a mapping, got {type(d).__name__}", file=str(config), field="top level",
                          fix="write the run file's sections as keys (data:, fit:, ...), as for `imucal calibrate`")
    d = {k: v for k, v in d.items()}
    if isinstance(d.get("data"), Mapping):
        d["data"] = {k: v for k, v in d["data"].items() if k not in FILE_KEYS}
    return _settings(d, str(config), "top level")


@dataclass(frozen=True)
class UnitEntry:
    """One unit of a YAML manifest's ``units:`` list (id, files and settings are checked by _collect)."""

    id: Any = field(metadata=rule(fix="give each unit an id"))
    data: Any = None
    gyro_data: Any = None
    settings: Any = None


@dataclass(frozen=True, kw_only=True)
class ManifestFile:
    """A YAML manifest as written (module docstring), checked in this order."""

    format: Literal["imucal-fleet-manifest"] = field(default=FORMAT, metadata=rule(
        msg="format {value} is not a fleet manifest", fix=f"format: {FORMAT}"))
    format_version: Literal[1] = field(default=FORMAT_VERSION, metadata=rule(
        msg="format_version {value} is not supported", fix=f"this imucal reads version {FORMAT_VERSION}"))
    config: str | None = field(default=None, metadata=rule(msg="{value} is not a file name"))
    settings: Any = None  #: run-file sections (_settings)
    tolerances: Tolerances = Tolerances()
    units: str | tuple[UnitEntry, ...] | None = field(default=None, metadata=rule(
        msg="units must be a list or a CSV file name, got {value}"))
    folder: str | None = None
    pattern: str | None = None

    def __post_init__(self) -> None:
        if (self.units is None) == (self.folder is None):
            raise ImucalError("give either units: or folder:", field="units",
                              fix="units: [{id: U1, data: U1.csv}, ...], units: listing.csv, or folder: recordings/")
        if self.pattern is not None and self.folder is None:
            raise ImucalError("pattern is used only with folder:", field="pattern",
                              fix="add folder: DIR, or drop pattern")
        if self.pattern is not None and ("/" in self.pattern or ".." in self.pattern):
            raise ImucalError("pattern must be a file pattern such as *.csv", field="pattern",
                              fix="give a file name pattern without / or .., e.g. pattern: '*.csv'")


def manifest_from_dict(d: Any, path: str, shared: dict | None = None) -> Manifest:
    """A Manifest from a YAML mapping (``path`` names it in messages and anchors relative paths)."""
    check_structure(d, path, paths=True)
    m = fill(ManifestFile, d, path)
    base = Path(path).parent
    if shared is None:
        shared = _run_file_settings(base / m.config) if m.config is not None else {}
    elif m.config is not None:
        raise ImucalError("the manifest names a run file and --config gives another", file=path, field="config",
                          fix="give the shared settings once")
    shared = _merge(shared, _settings(m.settings, path, "settings"))
    if m.folder is not None:
        listing = _folder_units(base / m.folder, m.pattern or "*.csv", path, "folder")
    elif isinstance(m.units, str):
        csv_path = base / m.units
        text = read_input_text(csv_path, field="units", fix="give a CSV listing: unit,data[,gyro_data]")
        listing = _csv_units(text, str(csv_path))
        base = csv_path.parent
    else:
        listing = [(u.id, u.data, u.gyro_data, _settings(u.settings, path, f"units[{i}].settings"), f"units[{i}]")
                   for i, u in enumerate(m.units or ())]
    return Manifest(source=path, units=_collect(listing, shared, base, path), tolerances=m.tolerances)
