"""Every sensor kind imucal knows, by the name its calibration file section carries (issue 26).

The accelerometer's description depends on its effects (imucal.model.sensor.build_model); every other
kind names the module and function that build its description, imported only when a file or run holds
one (measured start-up: an accelerometer-only run never builds the others). A new sensor adds one line; a
module whose description takes terms (the gyroscope's temperature terms) also has ``described(name)``, the
description a file's model name names (None when it names none): the magnetometer's mounting and output unit
are read back from its name so.
"""
from __future__ import annotations

import importlib

from imucal.errors import ImucalError, short
from imucal.model.sensor import ACCELEROMETER, GYROSCOPE, MAGNETOMETER, SensorModel

#: kind -> (module, function) of its description
DESCRIPTIONS: dict[str, tuple[str, str]] = {
    GYROSCOPE: ("imucal.model.gyroscope", "gyro_model"),
    MAGNETOMETER: ("imucal.mag.model", "mag_model"),
}
#: the order of a calibration's sensors: the accelerometer (the frame) first, then as listed
KINDS = (ACCELEROMETER, *DESCRIPTIONS)


def describe(kind: str, label: str | None = None, where: str | None = None, file: str | None = None) -> SensorModel:
    """The description of a sensor ``kind``; ``label`` (a file's model name) must be its name."""
    if kind not in DESCRIPTIONS:
        raise ImucalError(f"unknown sensor {short(kind)}", file=file, field=where or "sensors",
                          fix=f"this imucal knows {', '.join(KINDS)}; upgrade imucal for others")
    module, fn = DESCRIPTIONS[kind]
    mod = importlib.import_module(module)
    model = getattr(mod, fn)()
    if label is not None and label != model.name and hasattr(mod, "described"):
        # a description with terms or constants (the gyroscope's bias(T), the magnetometer's mounting): the module
        # reads its own name back
        model = mod.described(label) or model
    if label is not None and label != model.name:
        raise ImucalError(f"model {short(label)} is not this imucal's {kind} model {model.name!r}", file=file,
                          field=f"{where or kind}.model", fix="regenerate the file with this imucal, or upgrade imucal")
    return model


def parameter_units(kind: str, model: SensorModel, raw_unit: str) -> dict[str, str]:
    """Each parameter's unit as the ``kind`` module's own parameter builder writes it for readings in
    ``raw_unit`` (its ``parameter_units(model, raw_unit)``): what a file's unit labels are checked against."""
    module, _ = DESCRIPTIONS[kind]
    return importlib.import_module(module).parameter_units(model, raw_unit)
