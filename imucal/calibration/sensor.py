"""One calibrated sensor, whatever the sensor (issue 26): its description, fitted Parameters with standard
errors, and fit statistics. A Calibration holds a list of them; the file section, apply, the C and the
exports read every sensor through this one value.

A sensor's map is its description's CasADi ``apply`` (imucal.model.sensor.SensorModel), evaluated by numpy
generated from it (imucal.solve.vectorize.apply_values). Where it is affine in its raw reading and its
inputs (every sensor without a nonlinear effect), ``affine`` gives the map for people and other tools,
y = A raw + c + B inputs, and ``forward`` the same map as the peers write it, raw - s = P y + F inputs.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from imucal.errors import ImucalError
from imucal.model.parameters import Parameters
from imucal.model.channels import COVARIATES
from imucal.model.sensor import SensorModel
from imucal.solve.vectorize import apply_values


@dataclass(frozen=True)
class Affine:
    """y = A raw + c + B inputs (SensorModel.affine at the values)."""

    A: np.ndarray  #: (3, 3) [output unit per raw unit]
    c: np.ndarray  #: (3,) [output unit]
    B: np.ndarray  #: (3, k) [output unit per input unit]


@dataclass(frozen=True)
class Forward:
    """The same map, forward: raw - s = P y + F inputs (P = A^-1, F = -P B, s = -P c)."""

    P: np.ndarray  #: (3, 3) [raw unit per output unit]
    F: np.ndarray  #: (3, k) [raw unit per input unit]
    s: np.ndarray  #: (3,) [raw unit]: the raw reading at y = 0 and inputs 0 (a bias, a shift, a hard iron)


@dataclass(frozen=True)
class SensorCalibration:
    """A calibrated sensor in the accelerometer's output frame."""

    model: SensorModel = field(compare=False)
    params: Parameters
    std: Mapping[str, float]  #: every parameter's standard error; NaN where not determined
    raw_unit: str = "raw"  #: the unit of its raw readings
    fit: Mapping[str, Any] = field(default_factory=dict)  #: fit statistics (status, chi2, dof, its evidence's)

    @property
    def kind(self) -> str:
        return self.model.kind

    @property
    def values(self) -> np.ndarray:
        return np.array(self.params.values(), float)

    def vector(self, names: Sequence[str], std: bool = False) -> np.ndarray:
        """The values (or standard errors) of ``names``, in order."""
        return np.array([float(self.std.get(n, float("nan"))) if std else self.params[n].value for n in names])

    @property
    def covariates(self) -> tuple[str, ...]:
        """The covariates its map reads (temp: the gyroscope's bias(T) terms), in the order of its inputs."""
        return tuple(k for k in self.model.inputs if k in COVARIATES)

    def reference_inputs(self) -> dict[str, float]:
        """Each covariate at its reference (temp: the terms' T_ref, time: t0, or 0 from the start)."""
        out = {}
        for key in self.covariates:
            refs = [f"{e.name}_{r}" for e in self.model.effects if key in e.covariates for r in ("tref", "t0")]
            out[key] = next((self.params[n].value for n in refs if n in self.params), 0.0)
        return out

    def at_reference(self) -> "SensorCalibration":
        """This sensor with its covariates held at ``reference_inputs``: a map affine in its raw reading and
        its other inputs (the file's apply map for people, the C's header, the peers that hold no
        temperature term). Itself when its map reads no covariate."""
        if not self.covariates:
            return self
        ref = self.reference_inputs()
        f = self.model.functions["apply"]
        keep = tuple(k for k in self.model.inputs if k not in ref)
        raw, inp, p = ca.SX.sym("raw", 3), ca.SX.sym("inputs", len(keep)), ca.SX.sym("p", len(self.model.names))
        full = ca.vertcat(*[inp[keep.index(k)] if k in keep else ca.SX(ref[k]) for k in self.model.inputs])
        g = ca.Function("apply", [raw, inp, p], [f(raw, full, p)], ["raw", "inputs", "p"], ["calibrated"])
        at = ", ".join(f"{k} = {v:.6g}" for k, v in ref.items())
        model = replace(self.model, effects=(), inputs=keep, functions={"apply": g},
                        label=f"{self.model.name} at {at}")
        return replace(self, model=model)

    def affine(self) -> Affine:
        """The map as y = A raw + c + B inputs; refused for a map that is not affine (a nonlinear effect)."""
        if self.model.affine is None:
            raise ImucalError(f"the {self.kind} map {self.model.name} is not affine in its readings",
                              field=self.kind, fix="evaluate it with apply")
        A, c, B = (np.asarray(v, float) for v in self.model.affine(self.values))
        return Affine(A, c.ravel(), B.reshape(3, len(self.model.inputs)))

    def forward(self) -> Forward:
        """The map forward, raw - s = P y + F inputs, as the peers' formats write it."""
        a = self.affine()
        P = np.linalg.inv(a.A)
        return Forward(P, -P @ a.B, -P @ a.c)

    def reads_inputs(self) -> bool:
        """Its map depends on its inputs at these values (the gyroscope's g-sensitivity selected)."""
        return self.model.affine is None or bool(np.any(self.affine().B)) if self.model.inputs else False

    def apply(self, raw: np.ndarray, inputs: np.ndarray | None = None) -> np.ndarray:
        """Calibrated readings (N, 3) or (3,) of raw readings; ``inputs`` (N, k) or (k,) the map's other inputs
        for the same samples (covariates, or another sensor's calibrated output: SensorModel.inputs)."""
        raw = np.asarray(raw, float)
        one = raw.shape == (3,)
        raw = np.atleast_2d(raw)
        if raw.ndim != 2 or raw.shape[1] != 3:
            raise ImucalError(f"{self.kind} data must have shape (N, 3) or (3,), got {raw.shape}",
                              field=f"raw_{self.kind}", fix="pass one row of three raw readings (x, y, z) per sample")
        if inputs is None and self.reads_inputs():
            raise ImucalError(f"this {self.kind} calibration reads {', '.join(self.model.inputs)}", field="inputs",
                              fix=f"pass {', '.join(self.model.inputs)} of the same samples")
        k = len(self.model.inputs)
        inp = None if inputs is None else np.broadcast_to(np.atleast_2d(np.asarray(inputs, float)), (raw.shape[0], k))
        out = apply_values(self.model, self.values, raw, inp)
        return out[0] if one else out


def apply_sensors(sensors: Sequence[SensorCalibration], raw: Mapping[str, np.ndarray | None],
                  columns: Mapping[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Every sensor whose raw readings ``raw`` holds (by kind), in order: each reads its inputs from
    ``columns`` (covariates by key: temp, time) or from an earlier sensor's calibrated output columns
    (ax, ay, az ...). Returns {kind: calibrated (N, 3)}."""
    have = {k: np.asarray(v, float) for k, v in (columns or {}).items()}
    out: dict[str, np.ndarray] = {}
    for s in sensors:
        r = raw.get(s.kind)
        if r is None:
            continue
        missing = [k for k in s.model.inputs if k not in have]
        if missing:
            raise ImucalError(f"the {s.kind} calibration reads {', '.join(missing)}, which the data do not give",
                              field=f"data.columns.{missing[0]}", fix=f"give {', '.join(missing)} with the readings")
        n = np.atleast_2d(r).shape[0]
        inputs = np.column_stack([np.broadcast_to(have[k], (n,)) for k in s.model.inputs]) if s.model.inputs else None
        y = s.apply(r, inputs)
        out[s.kind] = y
        have.update({c: np.atleast_2d(y)[:, i] for i, c in enumerate(s.model.output.columns)})
    return out
