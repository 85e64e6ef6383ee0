"""The fixed parts of one discovery (data, template run file) and the fits it makes; the shared helpers
that name a model's effects and test a fit against the noise."""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from imucal.config.run import RunConfig
from imucal.model.channels import temperature_rate
from imucal.model.effects import EFFECTS, AxisEffect, fit_to_data, given_names, make_effect, prepare_parameters
from imucal.model.sensor import build_model
from imucal.pipeline import CalibrationRun, fit_data, make_parameters, observability
from imucal.solve.f_test import f_sf
from imucal.solve.fit import FitData, FitResult, fit
from imucal.solve.stats import chi2_sf

#: Effects in the grammar's order (the order models list them and reports show them).
EFFECT_ORDER = {n: i for i, n in enumerate(EFFECTS)}
#: A model's effects as {effect name: axes}.
Effects = dict[str, tuple[int, ...]]


def canonical(effects: Effects) -> list[AxisEffect]:
    """The effect objects of ``effects`` in the grammar's order."""
    return [make_effect(n, ax) for n, ax in sorted(effects.items(), key=lambda kv: EFFECT_ORDER[kv[0]])]


def as_dict(effects: Sequence) -> Effects:
    """{name: axes} of effect objects (an effect listed twice has the union of its axes)."""
    out: Effects = {}
    for e in effects:
        out[e.name] = tuple(sorted(set(out.get(e.name, ())) | set(e.axes)))
    return out


def label(name: str, axes: tuple[int, ...]) -> str:
    """``name[xy]``: an effect on its axes (an angle term's: ``angle_temperature[phi,theta]``)."""
    return f"{name}[{EFFECTS[name].axis_label(axes)}]"


def labels(names: Sequence[str], effects: Effects) -> tuple[str, ...]:
    """The labels of the effects ``names`` (each once, in the order given) on their axes in ``effects``."""
    return tuple(label(n, effects[n]) for n in dict.fromkeys(names) if n in effects)


def p_noise(res: FitResult) -> float:
    """p of the chi-square test of a fit's residual against the noise of its rows."""
    return chi2_sf(res.chi2, res.dof) if res.dof > 0 else 1.0


def p_lr(lr: float, k: int, res: FitResult, alpha_noise: float) -> float:
    """p of a likelihood-ratio statistic scaled by max(1, chi2/dof): chi-square(k) while the fit's
    residual is consistent with the noise (the noise is known), F(k, dof) when it is not (the
    misfit scale is then estimated from the fit, and chi-square would overstate the evidence)."""
    if res.dof > 0 and res.redchi > 1.0 and p_noise(res) < alpha_noise:
        return f_sf(lr / k, k, res.dof)
    return chi2_sf(lr, k)


class Problem:
    """The fixed parts of one discovery: data, template config, and the fits it makes."""

    def __init__(self, config: RunConfig, base: CalibrationRun, step: Callable[[], None] | None = None) -> None:
        self.step = step or (lambda: None)  #: called after every fit (a progress bar, imucal.report.progress)
        self.config = config
        self.run = base
        self.iv = base.intervals
        self.rec = base.recording
        self.gravity = base.calibration.gravity
        self.cov = dict(self.iv.covariates)  # (with the holds' own dT/dt when the samples were read whole)
        if "temp_rate" not in self.cov:  # a file read in chunks: the slope across the interval means
            self.cov["temp_rate"] = None if self.iv.temp is None else temperature_rate(self.iv.t_mid, self.iv.temp)
        g = base.guess  # the interval directions of imucal.pipeline.initial_guess
        d = (self.iv.mean - g.s) / g.b
        self.directions = d / np.linalg.norm(d, axis=1, keepdims=True)

    def parameters(self, effects: list[AxisEffect], start: dict[str, float], check: bool = True):
        model = build_model(effects)
        params = make_parameters(self.run.guess, self.config, self.gravity, model, self.rec.unit)
        if check:
            params = prepare_parameters(model.effects, params, self.cov, self.iv.n, self.rec.source)
        else:  # the screening model holds every candidate at once: only its Jacobian is used
            params = fit_to_data(model.effects, params, self.cov)
        given = set(given_names(model.effects))  # (a step's time: set by discovery, fixed in the fit)
        keep = {n: v for n, v in start.items() if n in params.names and (not params[n].fixed or n in given)}
        return model, params.with_values(keep)

    def data(self, model) -> FitData:
        return fit_data(model, self.iv, self.rec, "means", self.rec.source)

    def undetermined(self, effects: list[AxisEffect], res: FitResult) -> tuple[str, ...]:
        """What the calibration's observability check (imucal.pipeline.observability) would call
        undetermined in the model ``effects`` at the values of ``res``."""
        model = build_model(effects)
        return observability(model, res.params, self.data(model), self.directions, self.gravity,
                             self.config.fit.angle_tolerance).undetermined

    def fit(self, effects: list[AxisEffect], start: dict[str, float]) -> FitResult:
        model, params = self.parameters(effects, start)
        res = fit(self.data(model), params, model, self.gravity, source=self.rec.source)
        self.step()
        return res
