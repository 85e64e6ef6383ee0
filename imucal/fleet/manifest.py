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
import io
import json
import math
import re
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Mapping

import yaml

from imucal import __version__
from imucal.config.limits import MAX_FLEET_UNITS
from imucal.config.run import FitSettings, GravitySpec, OutputSettings, RunConfig, config_from_dict
from imucal.data.load import DataSpec
from imucal.data.static import StaticSettings
from imucal.errors import ImucalError, short
from imucal.files.inputs import read_input_text
from imucal.files.yamlio import check_structure, key_text, read_yaml

FORMAT = "imucal-fleet-manifest"
FORMAT_VERSION = 1
#: A unit id names its output folder: letters, digits, '.', '_', '-', starting with a letter or digit.
UNIT_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}\Z")
#: Names the fleet report takes in DIR (imucal.fleet.report): no unit folder may take them.
REPORT_NAMES = re.compile(r"fleet(\.(csv|txt|parquet)|_.*\.png)\Z", re.IGNORECASE)
#: Run-file sections a manifest may set (output.dir is the batch's --out DIR/<unit>).
SECTIONS = ("data", "static", "gravity", "fit", "output")
#: Keys that name files: given per unit (data, gyro_data), never as shared settings.
FILE_KEYS = ("path", "gyro_path")
#: The keys of each section (a CSV override column is checked against them even when all its cells are empty).
SECTION_KEYS = {name: tuple(f.name for f in fields(cls)) for name, cls in (
    ("data", DataSpec), ("static", StaticSettings), ("gravity", GravitySpec), ("fit", FitSettings),
    ("output", OutputSettings))}
TOP_KEYS = ("format", "format_version", "config", "settings", "tolerances", "units", "folder", "pattern")
UNIT_KEYS = ("id", "data", "gyro_data", "settings")


@dataclass(frozen=True)
class Tolerances:
    """Pass/fail limits of one unit; None: not checked.

    ``bias_abs_max`` [m/s^2]: |s_i / b_i|, the zero-g reading of each axis in m/s^2.
    ``angle_deg_from_90_max`` [deg]: |angle - 90 deg| of phi, psi and theta.
    ``rms_max`` [m/s^2]: RMS of |a| - g over the static interval means.
    ``scale_min``, ``scale_max`` [raw per m/s^2]: range of each scale b_i.
    """

    bias_abs_max: float | None = None
    angle_deg_from_90_max: float | None = None
    rms_max: float | None = None
    scale_min: float | None = None
    scale_max: float | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                                  or v < 0):
                raise ImucalError(f"{short(v)} must be a non-negative number", field=f"tolerances.{f.name}",
                                  fix="e.g. tolerances: {bias_abs_max: 0.5, angle_deg_from_90_max: 0.5, "
                                      "rms_max: 0.01} (m/s^2 and degrees)")
        if self.scale_min is not None and self.scale_max is not None and self.scale_min > self.scale_max:
            raise ImucalError(f"scale_min {self.scale_min:g} is above scale_max {self.scale_max:g}",
                              field="tolerances.scale_min")

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
                              field=f"{where}.{'data' if role == 'path' else 'gyro_data'}")
        files[role] = str((base / v).resolve()) if not Path(v).is_absolute() else v
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
                    val = yaml.safe_load(c)
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
    if p.is_dir():
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
        raise ImucalError("top level must be a mapping", file=str(config), field="top level")
    d = {k: v for k, v in d.items()}
    if isinstance(d.get("data"), Mapping):
        d["data"] = {k: v for k, v in d["data"].items() if k not in FILE_KEYS}
    return _settings(d, str(config), "top level")


def manifest_from_dict(d: Any, path: str, shared: dict | None = None) -> Manifest:
    """A Manifest from a YAML mapping (``path`` names it in messages and anchors relative paths)."""
    check_structure(d, path)
    if not isinstance(d, Mapping):
        raise ImucalError("top level must be a mapping with units: or folder:", file=path, field="top level",
                          fix="see docs/fleet.md")
    unknown = [k for k in d if k not in TOP_KEYS]
    if unknown:
        raise ImucalError(f"unknown key {short(unknown[0])}", file=path, field=key_text(unknown[0]),
                          fix=f"allowed keys: {', '.join(TOP_KEYS)}")
    if "format" in d and d["format"] != FORMAT:
        raise ImucalError(f"format {short(d['format'])} is not a fleet manifest", file=path, field="format",
                          fix=f"format: {FORMAT}")
    if "format_version" in d and d["format_version"] != FORMAT_VERSION:
        raise ImucalError(f"format_version {short(d['format_version'])} is not supported", file=path,
                          field="format_version", fix=f"this imucal reads version {FORMAT_VERSION}")
    base = Path(path).parent
    if shared is None:
        shared = {}
        if d.get("config") is not None:
            if not isinstance(d["config"], str):
                raise ImucalError(f"{short(d['config'])} is not a file name", file=path, field="config")
            shared = _run_file_settings(base / d["config"])
    elif d.get("config") is not None:
        raise ImucalError("the manifest names a run file and --config gives another", file=path, field="config",
                          fix="give the shared settings once")
    shared = _merge(shared, _settings(d.get("settings"), path, "settings"))
    tol = d.get("tolerances")
    if tol is not None and not isinstance(tol, Mapping):
        raise ImucalError("must be a mapping", file=path, field="tolerances", fix="e.g. tolerances: {rms_max: 0.01}")
    allowed = [f.name for f in fields(Tolerances)]
    bad = [k for k in (tol or {}) if k not in allowed]
    if bad:
        raise ImucalError(f"unknown tolerance {short(bad[0])}", file=path, field=f"tolerances.{key_text(bad[0])}",
                          fix=f"allowed: {', '.join(allowed)}")
    try:
        tolerances = Tolerances(**dict(tol or {}))
    except ImucalError as exc:
        raise ImucalError(exc.message, file=path, field=exc.field, fix=exc.fix) from None
    has_units, has_folder = d.get("units") is not None, d.get("folder") is not None
    if has_units == has_folder:
        raise ImucalError("give either units: or folder:", file=path, field="units",
                          fix="units: [{id: U1, data: U1.csv}, ...], units: listing.csv, or folder: recordings/")
    if "pattern" in d and not has_folder:
        raise ImucalError("pattern is used only with folder:", file=path, field="pattern")
    if has_folder:
        pattern = d.get("pattern", "*.csv")
        if not isinstance(d["folder"], str) or not isinstance(pattern, str) or "/" in pattern or ".." in pattern:
            raise ImucalError("folder must be a folder name and pattern a file pattern such as *.csv", file=path,
                              field="folder")
        listing = _folder_units(base / d["folder"], pattern, path, "folder")
    elif isinstance(d["units"], str):
        csv_path = base / d["units"]
        text = read_input_text(csv_path, field="units", fix="give a CSV listing: unit,data[,gyro_data]")
        listing = _csv_units(text, str(csv_path))
        base = csv_path.parent
    elif isinstance(d["units"], list):
        listing = []
        for i, u in enumerate(d["units"]):
            where = f"units[{i}]"
            if not isinstance(u, Mapping):
                raise ImucalError("must be a mapping with id and data", file=path, field=where,
                                  fix="e.g. - {id: U0001, data: U0001.csv}")
            extra = [k for k in u if k not in UNIT_KEYS]
            if extra:
                raise ImucalError(f"unknown key {short(extra[0])}", file=path, field=f"{where}.{key_text(extra[0])}",
                                  fix=f"allowed keys: {', '.join(UNIT_KEYS)}")
            if "id" not in u:
                raise ImucalError("missing id", file=path, field=f"{where}.id", fix="give each unit an id")
            listing.append((u["id"], u.get("data"), u.get("gyro_data"),
                            _settings(u.get("settings"), path, f"{where}.settings"), where))
    else:
        raise ImucalError(f"units must be a list or a CSV file name, got {type(d['units']).__name__}", file=path,
                          field="units")
    return Manifest(source=path, units=_collect(listing, shared, base, path), tolerances=tolerances)
