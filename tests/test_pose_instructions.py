"""Plain-language pose instructions (imucal.analysis.pose_instructions, `imucal plan-poses`): the
face, edge or corner down and the tilt are right, checked by turning a board in the test."""
from __future__ import annotations

import json
import math
import re
from itertools import product

import numpy as np
import pytest

from imucal.analysis.pose_instructions import instruction

E = {f"{s}{a}": np.eye(3)[i] * (1 if s == "+" else -1) for (i, a), s in product(enumerate("XYZ"), "+-")}


def rot(axis: np.ndarray, deg: float) -> np.ndarray:
    """Right-handed rotation matrix about a unit axis (Rodrigues' matrix)."""
    k = np.asarray(axis, float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    t = math.radians(deg)
    return np.eye(3) * math.cos(t) + math.sin(t) * K + (1 - math.cos(t)) * np.outer(k, k)


def down_after(face: str, axis: np.ndarray, deg: float) -> np.ndarray:
    """Set the board on ``face`` (its outward normal points down), turn it by ``deg`` about its own
    ``axis``: where does down point in the board (sensor) frame?  R_board->world = R0 R_k, so
    down_board = R_k^T R0^T down_world = R_k^T n."""
    return rot(axis, deg).T @ E[face]


def angle(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), a @ b))


def test_flat_on_each_face():
    for name, v in E.items():  # up = v: the opposite face is down
        opposite = ("-" if name[0] == "+" else "+") + name[1]
        assert instruction(v).text == f"{opposite} face down ({name} up)"
    assert instruction([0, 0, 1]).text == "-Z face down (+Z up)"  # lying flat, top up
    assert instruction([0, 0, 1]).numbered(3) == "Pose 3: -Z face down (+Z up)"


def test_edges_and_corners():
    for v in product((-1, 0, 1), repeat=3):
        k = np.count_nonzero(v)
        if k < 2:
            continue
        down = -np.array(v)
        names = [f"{'+' if x > 0 else '-'}{a}" for x, a in zip(down, "XYZ") if x]
        text = instruction(np.array(v, float)).text
        expected = "/".join(names) + " edge down" if k == 2 else "".join(names) + " corner down"
        assert text.startswith(expected), (v, text)


def test_face_down_then_tilt_about_an_axis():
    """The issue's example: +X face down, then tilt 35 degrees about Y."""
    up = -down_after("+X", E["+Y"], 35.0)
    assert instruction(up).text.startswith("+X face down, then tilt 35.0° about +Y")
    up = -down_after("-Z", E["-Y"], 20.0)  # lying flat, -X side lowered by 20 degrees
    inst = instruction(up)
    assert inst.text == "-Z face down, then tilt 20.0° about -Y (lowers the -X side)"
    assert inst.tilt_deg == pytest.approx(20.0) and inst.rests_on == "tilted face"


_TILT = re.compile(r"^([+-][XYZ]) face down, then tilt ([\d.]+)° about (?:([+-][XYZ])|the axis ([\d.]+)° from "
                   r"([+-][XYZ]) toward ([+-][XYZ])) \(lowers (?:the ([+-][XYZ]) side|the side ([\d.]+)° from "
                   r"([+-][XYZ]) toward ([+-][XYZ]))\)$")


def _direction(named: str | None, deg: str | None, a1: str | None, a2: str | None) -> np.ndarray:
    if named:
        return E[named]
    p = math.radians(float(deg))
    return math.cos(p) * E[a1] + math.sin(p) * E[a2]


def test_following_the_words_gives_the_planned_direction():
    """Random directions: read the sentence back, turn a board as it says, compare."""
    rng = np.random.default_rng(5)
    U = rng.normal(size=(300, 3))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    worst = 0.0
    for u in U:
        text = instruction(u).text
        m = _TILT.match(text)
        assert m, text
        face, tilt = m.group(1), float(m.group(2))
        k = _direction(m.group(3), m.group(4), m.group(5), m.group(6))
        side = _direction(m.group(7), m.group(8), m.group(9), m.group(10))
        d = down_after(face, k, tilt)
        worst = max(worst, angle(d, -u))
        assert side @ (-u) > 0  # the side said to go down does go down
        assert tilt <= math.degrees(math.acos(1 / math.sqrt(3))) + 0.05  # never more than to a corner
    assert worst < 0.15  # degrees: the sentence rounds angles to 0.1 degree


def test_plan_poses_writes_instructions_and_drawings(run_cli, tmp_path):
    js, png = tmp_path / "plan.json", tmp_path / "poses.png"
    r = run_cli(["plan-poses", "--scheme", "faces+edges", "--no-compare", "--json", js, "--plot", png])
    assert r.code == 0, r.err
    plan = json.loads(js.read_text())
    assert len(plan["instructions"]) == len(plan["poses"]) == 18
    for k, (u, text) in enumerate(zip(plan["poses"], plan["instructions"])):
        assert text == instruction(u).numbered(k + 1)
        assert instruction(u).text in r.out
    assert sum("face down (" in t for t in plan["instructions"]) == 6
    assert sum(" edge down" in t for t in plan["instructions"]) == 12
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    again = run_cli(["plan-poses", "--evaluate", js, "--no-compare"])  # the written plan reads back
    assert again.code == 0 and instruction(plan["poses"][0]).text in again.out
