"""The magnetometer's ArduPilot and PX4 parameters (issue 26), read from its SensorCalibration's affine map.

Both autopilots correct the field with an offset and a symmetric 3x3 matrix, and rotate it by a mounting:
  ArduPilot  libraries/AP_Compass/AP_Compass_Backend.cpp: rotate_field (COMPASS_ORIENT for an external
             compass), then correct_field: "mag += offsets; mag = mat * mag", mat symmetric with
             COMPASS_DIA_X/Y/Z on the diagonal and COMPASS_ODI_X/Y/Z at (0,1), (0,2), (1,2);
             COMPASS_OFS_X/Y/Z in milligauss (Compass.cpp: @Units: milligauss).
             h = M (Rot raw + OFS)
  PX4        src/lib/sensor_calibration/Magnetometer.hpp, Correct(): _rotation * (_scale * (data - _offset)),
             _scale symmetric from CAL_MAG0_XSCALE.. on the diagonal and CAL_MAG0_XODIAG/YODIAG/ZODIAG at
             (0,1), (0,2), (1,2) (Magnetometer.cpp set_offdiagonal); CAL_MAG0_XOFF.. in gauss; CAL_MAG0_ROT.
             h = Rot S (raw - OFF)
imucal's map h = A (raw - s), A = R P E^-T diag(1/b) (imucal.mag.model), factored by the polar decomposition
P^T A = Q S (S symmetric positive, Q a rotation): PX4's S, OFF = s, Rot = P; ArduPilot's M = P S P^T,
OFS = -P s, Rot = P (then M (P raw + OFS) = P S (raw - s)). Q, the magnetometer's rotation from the
accelerometer's frame beyond the mounting, is held by neither: it is left out, its angle stated.
Units: both read a field unit (ArduPilot milligauss, PX4 gauss); a calibration of readings in counts is refused.
"""
from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass

import numpy as np

from imucal.calibration.frozen import Calibration
from imucal.calibration.sensor import SensorCalibration
from imucal.errors import ImucalError

AXES = ("X", "Y", "Z")
ARDUPILOT_OFS = tuple(f"COMPASS_OFS_{a}" for a in AXES)
ARDUPILOT_DIA = tuple(f"COMPASS_DIA_{a}" for a in AXES)
ARDUPILOT_ODI = tuple(f"COMPASS_ODI_{a}" for a in AXES)
ARDUPILOT_ORIENT = "COMPASS_ORIENT"
PX4_OFF = tuple(f"CAL_MAG0_{a}OFF" for a in AXES)
PX4_SCALE = tuple(f"CAL_MAG0_{a}SCALE" for a in AXES)
PX4_ODIAG = tuple(f"CAL_MAG0_{a}ODIAG" for a in AXES)
PX4_ROT = "CAL_MAG0_ROT"
#: The off-diagonal entries both autopilots hold, in the order of their X, Y, Z parameters.
OFF_DIAGONAL = ((0, 1), (0, 2), (1, 2))
#: Field units in microtesla (imucal.mag.units.FIELD_UNITS): ArduPilot's milligauss, PX4's gauss.
MILLIGAUSS_UT, GAUSS_UT = 0.1, 100.0
#: The rotations both autopilots name (AP_Math/rotations.h, PX4 conversion/rotation.h: one enum), those that
#: are axis permutations: the matrix is Rz(yaw) Ry(pitch) Rx(roll) of the angles in the name.
ROTATIONS = {0: "NONE", 2: "YAW_90", 4: "YAW_180", 6: "YAW_270", 8: "ROLL_180", 10: "ROLL_180_YAW_90",
             12: "PITCH_180", 14: "ROLL_180_YAW_270", 16: "ROLL_90", 18: "ROLL_90_YAW_90", 20: "ROLL_270",
             22: "ROLL_270_YAW_90", 24: "PITCH_90", 25: "PITCH_270", 26: "PITCH_180_YAW_90", 27: "PITCH_180_YAW_270",
             28: "ROLL_90_PITCH_90", 29: "ROLL_180_PITCH_90", 30: "ROLL_270_PITCH_90", 31: "ROLL_90_PITCH_180",
             32: "ROLL_270_PITCH_180", 33: "ROLL_90_PITCH_270", 34: "ROLL_180_PITCH_270", 35: "ROLL_270_PITCH_270",
             36: "ROLL_90_PITCH_180_YAW_90", 37: "ROLL_90_YAW_270"}


def rotation_matrix(name: str) -> np.ndarray:
    """The rotation of an enum name: Rz(yaw) Ry(pitch) Rx(roll), exact for multiples of 90 deg."""
    ang = {k.lower(): math.radians(float(v)) for k, v in re.findall(r"(ROLL|PITCH|YAW)_(\d+)", name)}
    c = {k: round(math.cos(ang.get(k, 0.0))) for k in ("roll", "pitch", "yaw")}
    s = {k: round(math.sin(ang.get(k, 0.0))) for k in ("roll", "pitch", "yaw")}
    rx = np.array([[1, 0, 0], [0, c["roll"], -s["roll"]], [0, s["roll"], c["roll"]]])
    ry = np.array([[c["pitch"], 0, s["pitch"]], [0, 1, 0], [-s["pitch"], 0, c["pitch"]]])
    rz = np.array([[c["yaw"], -s["yaw"], 0], [s["yaw"], c["yaw"], 0], [0, 0, 1]])
    return (rz @ ry @ rx).astype(float)


def rotation_enum(P: np.ndarray) -> int | None:
    """The autopilots' rotation number whose matrix is the signed permutation P (None: not named)."""
    return next((k for k, n in ROTATIONS.items() if np.array_equal(rotation_matrix(n), np.round(P))), None)


@dataclass(frozen=True)
class MagFactors:
    """h = P Q S (raw - s) in one field unit: the autopilots' numbers and what they leave out."""

    P: np.ndarray  #: the mounting (a signed permutation)
    rotation: int  #: its number in the autopilots' rotation enum
    Q: np.ndarray  #: the rotation beyond the mounting (held by neither autopilot)
    S: np.ndarray  #: the symmetric soft iron [1]
    s: np.ndarray  #: the hard iron [uT]

    @property
    def dropped_deg(self) -> float:
        """Q's angle [deg]: the heading error a level vehicle gets at most from leaving it out."""
        return math.degrees(math.acos(min(1.0, max(-1.0, (np.trace(self.Q) - 1) / 2))))


def _to_ut(unit: str, what: str, fmt: str) -> float:
    from imucal.mag.units import FIELD_UNITS

    if unit not in FIELD_UNITS:
        raise ImucalError(f"the magnetometer's {what} unit {unit!r} is not a field unit", field=f"magnetometer.units",
                          fix=f"{fmt} applies its numbers to a field in "
                              f"{'milligauss' if fmt == 'ArduPilot' else 'gauss'}: calibrate readings given in uT, "
                              f"gauss or mG (mag.unit) with the field given (--mag-field)")
    return FIELD_UNITS[unit]


def factors(m: SensorCalibration, fmt: str) -> MagFactors:
    """The polar factors of the magnetometer's map in microtesla per microtesla (P^T A = Q S)."""
    from imucal.mag.model import permutation

    k_in, k_out = _to_ut(m.raw_unit, "raw", fmt), _to_ut(m.model.output.unit, "output", fmt)
    a, f = m.affine(), m.forward()
    A = a.A * k_out / k_in  # uT per uT
    P = permutation(m.model)
    U, sv, Vt = np.linalg.svd(P.T @ A)
    Q = U @ Vt
    S = Vt.T @ np.diag(sv) @ Vt
    rot = rotation_enum(P)
    if rot is None:  # every proper signed permutation is named; a hand-edited file could hold another
        raise ImucalError(f"the mounting {m.model.name} has no {fmt} rotation number", field="magnetometer.model",
                          fix="regenerate the file with `imucal calibrate`")
    return MagFactors(P, rot, Q, (S + S.T) / 2, f.s * k_in)


def magnetometer(cal: Calibration) -> SensorCalibration | None:
    return cal.sensor("magnetometer")


#: A rotation beyond the mounting below this is not worth a note [deg]: the symmetric fit's, held to its
#: constraint's 1e-6 (imucal.mag.model.CONSTRAINT_SIGMA), is 1e-4 deg.
NEGLIGIBLE_ROTATION_DEG = 0.01


#: [mG] ArduPilot's COMPASS_OFFS_MAX (AP_Compass.cpp: default AP_COMPASS_OFFSETS_MAX_DEFAULT, @Range 500 3000):
#: its arming check ("Compass offsets too high", AP_Arming.cpp) refuses offsets longer than it.
ARDUPILOT_OFFS_MAX, ARDUPILOT_OFFS_MAX_LIMIT = 1800.0, 3000.0


def _offsets_note(ofs: np.ndarray) -> tuple[str, ...]:
    """ArduPilot's arming check on |COMPASS_OFS| [mG], said when this calibration's offsets fail it."""
    n = float(np.linalg.norm(ofs))
    if n <= ARDUPILOT_OFFS_MAX:
        return ()
    fix = (f"set COMPASS_OFFS_MAX to at least {math.ceil(n)}" if n <= ARDUPILOT_OFFS_MAX_LIMIT else
           f"beyond the {ARDUPILOT_OFFS_MAX_LIMIT:g} mG COMPASS_OFFS_MAX allows: mount the magnetometer away from the "
           "iron that offsets it")
    return (f"|COMPASS_OFS| = {n:.4g} mG exceeds COMPASS_OFFS_MAX's default {ARDUPILOT_OFFS_MAX:g} mG: ArduPilot "
            f"refuses to arm ('Compass offsets too high'); {fix}",)


#: PX4's parameter metadata range of CAL_MAGn_{X,Y,Z}SCALE (src/modules/sensors/module.yaml: min 0.1, max 3.0). The
#: offsets have none there, and sensor_calibration/Magnetometer.cpp reads them as set; the pre-arm check
#: (commander/HealthAndArmingChecks/checks/magnetometerCheck.cpp) asks a CAL_MAGn_ID equal to the device's id, not a
#: bound on them: no limit on the offsets is stated here.
PX4_SCALE_RANGE = (0.1, 3.0)


def _px4_scale_note(S: np.ndarray) -> tuple[str, ...]:
    """The diagonal of PX4's S outside the range its parameter metadata gives CAL_MAGn_*SCALE, said."""
    lo, hi = PX4_SCALE_RANGE
    out = [f"{n} = {v:.4g}" for n, v in zip(PX4_SCALE, np.diag(S)) if not lo <= v <= hi]
    if not out:
        return ()
    return (f"{', '.join(out)} outside the range PX4's parameter metadata gives the scales ({lo:g} to {hi:g}, "
            "src/modules/sensors/module.yaml): a ground station may not take it; a soft iron that large means iron "
            "close to the magnetometer: mount it away from it",)


def _note(f: MagFactors, fmt: str) -> tuple[str, ...]:
    if f.dropped_deg < NEGLIGIBLE_ROTATION_DEG:
        return ()
    return (f"the magnetometer's {f.dropped_deg:.3g} deg rotation from the accelerometer's frame beyond its mounting "
            f"is not held by {fmt} (a symmetric soft iron and a mounting only): its headings differ by up to that",)


def ardupilot(cal: Calibration) -> tuple[list[str], list[tuple[str, float | int]], tuple[str, ...]]:
    """(header lines, parameters, notes) of the magnetometer in an ArduPilot file; nothing without one."""
    m = magnetometer(cal)
    if m is None:
        return [], [], ()
    f = factors(m, "ArduPilot")
    M, ofs = f.P @ f.S @ f.P.T, -(f.P @ f.s) / MILLIGAUSS_UT
    head = ["Magnetometer (AP_Compass_Backend.cpp: rotate_field by COMPASS_ORIENT, then correct_field):",
            "h = M (COMPASS_ORIENT raw + COMPASS_OFS), M symmetric: COMPASS_DIA on its diagonal, COMPASS_ODI off it;",
            f"COMPASS_OFS in milligauss; COMPASS_ORIENT = {f.rotation} ({ROTATIONS[f.rotation]}) is imucal's mounting "
            f"{m.model.name} (for an external compass; an internal one's driver rotates it)."]
    vals: list[tuple[str, float | int]] = [*zip(ARDUPILOT_OFS, map(float, ofs)),
                                           *zip(ARDUPILOT_DIA, map(float, np.diag(M))),
                                           *zip(ARDUPILOT_ODI, (float(M[i, j]) for i, j in OFF_DIAGONAL)),
                                           (ARDUPILOT_ORIENT, f.rotation)]
    return head, vals, _note(f, "ArduPilot") + _offsets_note(ofs)


def px4(cal: Calibration) -> tuple[list[str], list[tuple[str, float | int]], tuple[str, ...]]:
    """(header lines, parameters, notes) of the magnetometer in a PX4 file; nothing without one."""
    m = magnetometer(cal)
    if m is None:
        return [], [], ()
    f = factors(m, "PX4")
    head = ["Magnetometer (Magnetometer.hpp Correct()): h = CAL_MAG0_ROT * (S (raw - CAL_MAG0_*OFF)), S symmetric:",
            f"CAL_MAG0_*SCALE on its diagonal, CAL_MAG0_*ODIAG off it; offsets in gauss; CAL_MAG0_ROT = {f.rotation} "
            f"({ROTATIONS[f.rotation]}) is imucal's mounting {m.model.name},",
            "for an external magnetometer: PX4 forces an internal one's to -1 and rotates it by the board's SENS_BOARD_ROT",
            "(sensor_calibration/Magnetometer.cpp). PX4 sets no limit on the offsets (no COMPASS_OFFS_MAX as ArduPilot",
            "has): its parameter metadata (module.yaml) gives CAL_MAGn_*OFF no range, and its pre-arm magnetometer check",
            "(magnetometerCheck.cpp) asks only a CAL_MAG0_ID equal to the device's id."]
    vals: list[tuple[str, float | int]] = [*zip(PX4_OFF, map(float, f.s / GAUSS_UT)),
                                           *zip(PX4_SCALE, map(float, np.diag(f.S))),
                                           *zip(PX4_ODIAG, (float(f.S[i, j]) for i, j in OFF_DIAGONAL)),
                                           (PX4_ROT, f.rotation)]
    return head, vals, _note(f, "PX4") + _px4_scale_note(f.S) + ("set CAL_MAG0_ID to your magnetometer's device id",)


def all_permutations_named() -> bool:
    """Every proper signed permutation has a rotation number (checked by the tests)."""
    perms = [np.array(p) * np.array(sg)[:, None] for p in itertools.permutations(np.eye(3)) for sg in
             itertools.product((1, -1), repeat=3)]
    return all(rotation_enum(P) is not None for P in perms if np.isclose(np.linalg.det(P), 1.0))
