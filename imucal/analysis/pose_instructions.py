"""Plain-language pose instructions: how to set the board down so that a planned direction is up.

A pose is given as the unit vector u in the sensor frame that points up (the accelerometer reading
a/|a| when still; imucal.analysis.simulate: raw = s + b g E^T u). The direction that points down
is d = -u. The instruction names what rests on the table:

- a face, when d is within SNAP_DEG of a face normal: "-Z face down (+Z up)";
- an edge or a corner, when d is within SNAP_DEG of the bisector of two or three faces;
- otherwise the nearest face, then a tilt of theta = angle(n, d) about the board axis
  k = (d x n) / |d x n| (right-hand rule), which lowers the board's side n x k.

Why that axis: tilting the board by +theta about its own axis k turns the sensor-frame down
vector from n to R_k(-theta) n = n cos(theta) - (k x n) sin(theta), and with k as above
k x n = (n cos(theta) - d) / sin(theta), so the result is d (Rodrigues' formula).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import product

import numpy as np

AXES = "XYZ"
#: A down direction within this angle of a face normal, edge or corner bisector is named as it [deg]
#: (nobody sets a board down better than that by hand).
SNAP_DEG = 0.5
#: A tilt axis within this angle of a board axis is named as that axis [deg]: the angles are printed
#: to 0.1 deg, so the words are as exact as the numbers.
AXIS_SNAP_DEG = 0.05


def _signed(v: np.ndarray) -> str:
    """'+X-Z' for the cube direction v (entries -1, 0, +1)."""
    return "".join(f"{'+' if x > 0 else '-'}{AXES[i]}" for i, x in enumerate(v) if x != 0)


def _cube_directions() -> list[tuple[np.ndarray, str]]:
    """Face normals, edge and corner bisectors as (unit vector, kind)."""
    out = []
    for v in product((-1, 0, 1), repeat=3):
        k = sum(x != 0 for x in v)
        if k:
            out.append((np.array(v, float) / math.sqrt(k), {1: "face", 2: "edge", 3: "corner"}[k]))
    return out


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(a @ b)))


def name_in_plane(v: np.ndarray, normal_axis: int) -> tuple[str, float, str]:
    """Name a unit vector v lying in the plane of the two board axes other than ``normal_axis``:
    (nearest signed axis, angle from it [deg], signed axis it turns toward)."""
    others = [i for i in range(3) if i != normal_axis]
    comps = [(abs(v[i]), i) for i in others]
    (_, i1), (_, i2) = sorted(comps, reverse=True)
    a1 = f"{'+' if v[i1] > 0 else '-'}{AXES[i1]}"
    a2 = f"{'+' if v[i2] >= 0 else '-'}{AXES[i2]}"
    return a1, math.degrees(math.atan2(abs(v[i2]), abs(v[i1]))), a2


def _axis_phrase(v: np.ndarray, normal_axis: int) -> str:
    a1, phi, a2 = name_in_plane(v, normal_axis)
    return a1 if phi < AXIS_SNAP_DEG else f"the axis {phi:.1f}° from {a1} toward {a2}"


def _side_phrase(v: np.ndarray, normal_axis: int) -> str:
    a1, phi, a2 = name_in_plane(v, normal_axis)
    return f"the {a1} side" if phi < AXIS_SNAP_DEG else f"the side {phi:.1f}° from {a1} toward {a2}"


@dataclass(frozen=True)
class PoseInstruction:
    """How to set the board down for one pose."""

    up: tuple[float, float, float]  #: unit vector in the sensor frame that points up
    rests_on: str  #: "face", "edge", "corner" or "tilted face"
    down: str  #: what touches the table: "+X face", "+X/-Z edge", "+X+Y-Z corner"
    tilt_deg: float  #: tilt from the face down (0 unless rests_on == "tilted face") [deg]
    axis: tuple[float, float, float]  #: tilt axis, board frame, right-hand rule (zeros without tilt)
    text: str  #: the sentence, without the pose number

    def numbered(self, k: int) -> str:
        return f"Pose {k}: {self.text}"


def instruction(up: np.ndarray | list[float]) -> PoseInstruction:
    """The plain-language instruction that puts ``up`` (sensor frame) up."""
    u = np.asarray(up, float)
    u = u / np.linalg.norm(u)
    d = -u
    cube = _cube_directions()
    best, kind = max(cube, key=lambda c: float(c[0] @ d))
    zero = (0.0, 0.0, 0.0)
    if _angle_deg(best, d) <= SNAP_DEG:
        v = np.rint(best * math.sqrt(np.count_nonzero(np.abs(best) > 1e-9))).astype(int)
        if kind == "face":
            text = f"{_signed(v)} face down ({_signed(-v)} up)"
            return PoseInstruction(tuple(u), "face", f"{_signed(v)} face", 0.0, zero, text)
        if kind == "edge":
            faces = [_signed(np.eye(3, dtype=int)[i] * v[i]) for i in range(3) if v[i]]
            down = "/".join(faces) + " edge"
            text = f"{down} down (stand it on the edge between the {faces[0]} and {faces[1]} faces, each at 45° to the table)"
            return PoseInstruction(tuple(u), "edge", down, 0.0, zero, text)
        down = f"{_signed(v)} corner"
        text = (f"{down} down (stand it on that corner, each of its faces at "
                f"{math.degrees(math.acos(1 / math.sqrt(3))):.1f}° to the table)")
        return PoseInstruction(tuple(u), "corner", down, 0.0, zero, text)
    # Nearest face, then one tilt about an axis in that face.
    j = int(np.argmax(np.abs(d)))
    n = np.zeros(3)
    n[j] = math.copysign(1.0, d[j])
    theta = _angle_deg(n, d)
    k = np.cross(d, n)
    k /= np.linalg.norm(k)
    side = np.cross(n, k)
    face = _signed(n.astype(int))
    text = f"{face} face down, then tilt {theta:.1f}° about {_axis_phrase(k, j)} (lowers {_side_phrase(side, j)})"
    return PoseInstruction(tuple(u), "tilted face", f"{face} face", theta, tuple(float(x) for x in k), text)


def instructions(directions: np.ndarray) -> list[PoseInstruction]:
    return [instruction(u) for u in np.asarray(directions, float)]


def board_rotation(up: np.ndarray | list[float]) -> np.ndarray:
    """A rotation R (board frame -> world, world z up) with R^T (0, 0, 1) = up, for drawing.
    Its heading keeps the board axis least aligned with ``up`` pointing along world x."""
    u = np.asarray(up, float)
    u = u / np.linalg.norm(u)
    a = np.eye(3)[int(np.argmin(np.abs(u)))]
    ex = a - (a @ u) * u
    ex /= np.linalg.norm(ex)
    ey = np.cross(u, ex)
    return np.vstack([ex, ey, u])  # rows: world axes in board coordinates
