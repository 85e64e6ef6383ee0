"""A simulated fleet: N units drawn from a population around one nominal sensor, a few defective,
so that `imucal batch` can be exercised without hardware (`imucal simulate CONFIG --fleet N`).

Each unit's sensor is the simulation config's sensor with every axis's zero-g reading, scale
and angle drawn around it (Population spreads); a defective unit carries one far-off bias or
angle. Corrupt units get a damaged file, to rehearse the batch's error path.
"""
from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from imucal.analysis.simulate import SimulationConfig, frame_matrix
from imucal.config.limits import MAX_FLEET_UNITS, check_count
from imucal.errors import ImucalError, short
from imucal.files.output import OutputSet, check_outputs, write_bytes_atomic
from imucal.files.yamlio import dump_yaml
from imucal.fleet.manifest import FORMAT, FORMAT_VERSION

#: Tolerances written into the simulated manifest (m/s^2 and degrees).
DEFAULT_TOLERANCES = {"bias_abs_max": 0.5, "angle_deg_from_90_max": 0.5, "rms_max": 0.01}
DEFECTS = ("bias", "angle")
CORRUPTIONS = ("text in a number column", "cut after a few rows", "binary bytes")
MANIFEST_FILE, TRUTH_FILE, RECORDINGS = "manifest.yaml", "truth.csv", "recordings"


@dataclass(frozen=True)
class Population:
    """Unit-to-unit spreads (standard deviations) and the size of a defect."""

    bias: float = 0.05  #: zero-g reading of each axis [m/s^2]
    scale: float = 0.002  #: relative scale of each axis [-]
    angle: float = 0.05  #: each angle [deg]
    defect_bias: float = 2.0  #: added to one axis's zero-g reading of a "bias" defect [m/s^2]
    defect_angle: float = 1.5  #: added to one angle of an "angle" defect [deg] (inside the fit's +-2 %)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ImucalError(f"{f.name} {short(v)} must be a non-negative number", field="--spread",
                                  fix="e.g. --spread bias=0.05,scale=0.002,angle=0.05 (m/s^2, -, deg)")


def parse_spread(text: str) -> Population:
    """``bias=0.05,scale=0.002,angle=0.05`` (any subset of Population's fields) -> Population."""
    kw: dict[str, float] = {}
    names = [f.name for f in fields(Population)]
    for part in text.split(","):
        key, eq, val = part.partition("=")
        key = key.strip()
        if not eq or key not in names or key in kw:
            raise ImucalError(f"{short(part)} is not NAME=VALUE with a new NAME from {', '.join(names)}",
                              field="--spread", fix="e.g. --spread bias=0.05,angle=0.05")
        try:
            kw[key] = float(val)
        except ValueError:
            raise ImucalError(f"{short(val)} is not a number", field=f"--spread {key}",
                              fix=f"give {key}=NUMBER, e.g. --spread {key}=0.05") from None
    return Population(**kw)


@dataclass(frozen=True)
class SimUnit:
    id: str
    config: SimulationConfig
    defect: str | None
    corrupt: str | None


def draw_fleet(cfg: SimulationConfig, n: int, defective: int = 0, corrupt: int = 0,
               population: Population = Population()) -> list[SimUnit]:
    """N units around ``cfg.sensor``; ``defective`` and ``corrupt`` units chosen from the seed, apart."""
    check_count(n, "--fleet", 1, MAX_FLEET_UNITS)
    check_count(defective, "--defective", 0, n)
    check_count(corrupt, "--corrupt", 0, n - defective)
    rng = np.random.default_rng([cfg.seed, 7309])
    order = rng.permutation(n)
    kinds = {int(k): DEFECTS[i % len(DEFECTS)] for i, k in enumerate(order[:defective])}
    broken = {int(k): CORRUPTIONS[i % len(CORRUPTIONS)] for i, k in enumerate(order[defective:defective + corrupt])}
    nominal = cfg.sensor
    b0 = np.asarray(nominal.b, float)
    width = len(str(n))
    units = []
    for i in range(n):
        s = np.asarray(nominal.s, float) + rng.normal(0, population.bias, 3) * b0  # [m/s^2] -> raw
        b = b0 * (1 + rng.normal(0, population.scale, 3))
        ang = np.degrees(nominal.angles) + rng.normal(0, population.angle, 3)
        kind = kinds.get(i)
        axis, sign = int(rng.integers(3)), float(rng.choice([-1.0, 1.0]))
        if kind == "bias":
            s[axis] += sign * population.defect_bias * b[axis]
        elif kind == "angle":
            ang[axis] += sign * population.defect_angle
        sensor = replace(nominal, s=tuple(s), b=tuple(b), angles=tuple(np.radians(ang)))
        frame_matrix(np.asarray(sensor.angles))  # a valid frame, or a one-line refusal
        units.append(SimUnit(id=f"unit{i + 1:0{width}d}", config=replace(cfg, sensor=sensor, seed=int(rng.integers(2**62))),
                             defect=kind, corrupt=broken.get(i)))
    return units


def _damage(text: str, how: str) -> bytes:
    lines = text.splitlines(keepends=True)
    if how == "text in a number column":
        k = len(lines) // 2
        lines[k] = lines[k].replace(",", ",n/a", 1)
        return "".join(lines).encode()
    if how == "cut after a few rows":
        return "".join(lines[:6]).encode()
    return bytes(range(256)) * 8


def _truth_row(u: SimUnit) -> dict:
    v = u.config.sensor.values()
    row = {"unit": u.id, "defect": u.defect or "", "corrupt": u.corrupt or ""}
    row.update({k: repr(v[k]) for k in ("s1", "s2", "s3", "b1", "b2", "b3", "phi", "psi", "theta")})
    row.update({f"bias_{a}": repr(v[f"s{i + 1}"] / v[f"b{i + 1}"]) for i, a in enumerate("xyz")})
    return row


def write_fleet(units: list[SimUnit], out: Path, inputs: list[str], tolerances: dict | None = None,
                settings: dict | None = None, progress: Callable[[], None] | None = None) -> Path:
    """One CSV per unit in ``out``/recordings (a folder manifest too), truth.csv and manifest.yaml (shared
    ``settings``: run-file sections) in ``out``; each recording is written atomically, the manifest last.
    ``progress()`` is called after each unit's recording (imucal.report.progress). The manifest's path."""
    out = Path(out)
    manifest = {"format": FORMAT, "format_version": FORMAT_VERSION, "settings": dict(settings or {}),
                "tolerances": dict(DEFAULT_TOLERANCES if tolerances is None else tolerances),
                "units": [{"id": u.id, "data": f"{RECORDINGS}/{u.id}.csv"} for u in units]}
    buf = io.StringIO()
    rows = [_truth_row(u) for u in units]
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    recordings = [out / RECORDINGS / f"{u.id}.csv" for u in units]
    for path in recordings:  # before any work; unit ids are distinct, so are the names
        check_outputs(inputs, [path])
    check_outputs(inputs, [out / TRUTH_FILE, out / MANIFEST_FILE])
    for u, path in zip(units, recordings):  # one atomic file each; the manifest comes last
        text = u.config.run().to_csv_text()
        write_bytes_atomic(path, _damage(text, u.corrupt) if u.corrupt else text.encode())
        if progress is not None:
            progress()
    with OutputSet(inputs) as o:
        o.text(out / TRUTH_FILE, buf.getvalue())
        o.text(out / MANIFEST_FILE, "# imucal batch manifest.yaml --out DIR  (written by imucal simulate --fleet)\n"
               + dump_yaml(manifest, sort_keys=False))
    return out / MANIFEST_FILE
