"""One escaping function per text format imucal exports, so that no text a calibration carries (a
recording's file name, a date, a unit, an effect's name, a note) becomes a live line of another
tool's file. Every writer in imucal.export passes its text through the function of its format:

  ``#`` comments     PX4's QGroundControl .params, Kalibr's imu.yaml, the matrix CSV: ``hash_comment``.
                     A comment runs from ``#`` to the end of its line, and readers end lines at
                     \\n and \\r, Python's str.splitlines (MAVProxy, PyYAML's reader for Kalibr) also
                     at \\v \\f \\x1c-\\x1e \\x85 \\u2028 \\u2029, and PyYAML refuses a whole file with NUL
                     or another non-printable character. So the text is written in printable ASCII:
                     any other character as its Python escape (\\n, \\x0b, \\u2028), which keeps it
                     readable; a backslash is doubled, so the escape is not ambiguous.
  ArduPilot .param   ``ardupilot_comment``: the same text, on lines of at most ARDUPILOT_LINE
                     characters (see there).
  YAML values        ``yaml_flow`` (Kalibr's numbers, matrices and rostopic): PyYAML's own quoting,
                     on one line.
  JSON               json.dumps (mad-lab, matrix, the Arduino library.json): every control and
                     non-ASCII character escaped.
  C                  imucal.export.codegen.comment_text and plain_name (codegen, the Arduino layout).
imu_tk's .calib holds numbers only.
"""
from __future__ import annotations

import textwrap
from typing import Any

from imucal.files.yamlio import dump_yaml

#: Longest line ArduPilot's firmware reads whole from a parameter file: AP_Param's defaults-file
#: reader (AP_Param.cpp, read_param_defaults_file) reads ``char line[100]`` with
#: ``fgets(line, sizeof(line)-1, f)``, i.e. 98 characters with the newline, and parses the rest of a
#: longer line as a NAME,VALUE line of its own (a comment's tail "INS_ACCSCAL to ..." would set a value).
ARDUPILOT_LINE = 97
#: Longest free text shown in a comment (a recording's file name): NAME_MAX, the longest file name
#: on Linux, macOS and Windows file systems (255); a longer value is cut with "...".
MAX_FREE_TEXT = 255
#: Line width handed to PyYAML's emitter: it never folds a value onto a second line below this.
_YAML_WIDTH = 2**30


def escape_text(value: Any) -> str:
    """``value`` as printable ASCII on one line: every other character (and the backslash) as its
    Python escape, e.g. a newline as \\n and U+2028 as \\u2028."""
    text = value if isinstance(value, str) else str(value)
    return "".join(ch if " " <= ch <= "~" and ch != "\\" else ch.encode("unicode_escape").decode("ascii")
                   for ch in text)


def free_text(value: Any, max_len: int = MAX_FREE_TEXT) -> str:
    """A free-text value for a comment (a file name), cut to ``max_len`` characters; "?" for None."""
    text = "?" if value is None else (value if isinstance(value, str) else str(value))
    return text if len(text) <= max_len else text[:max_len] + "..."


def hash_comment(text: Any) -> str:
    """One ``#`` comment line (no newline) holding ``text`` (module docstring)."""
    return f"# {escape_text(text)}"


def ardupilot_comment(text: Any) -> list[str]:
    """``#`` comment lines holding ``text``, none longer than ARDUPILOT_LINE (broken at spaces where
    possible), so each is read whole by every ArduPilot loader and skipped as a comment."""
    body = escape_text(text)
    if len(body) + 2 <= ARDUPILOT_LINE:
        return [f"# {body}".rstrip()]
    return [f"# {ln}" for ln in textwrap.wrap(body, width=ARDUPILOT_LINE - 2, break_long_words=True,
                                               break_on_hyphens=False)]


def yaml_flow(value: Any) -> str:
    """``value`` as YAML flow text on one line that PyYAML reads back to the same value."""
    text = dump_yaml(value, default_flow_style=True, width=_YAML_WIDTH).strip()
    if text.endswith("\n..."):  # the document end marker PyYAML adds after a plain scalar, on a line of its own
        text = text[:-4].strip()  # (never the value's own "...": "/imu..." stayed "/imu")
    if "\n" in text:  # a single-quoted scalar spans lines at its line breaks: double quotes escape them
        text = dump_yaml(value, default_flow_style=True, width=_YAML_WIDTH, default_style='"').strip()
    return text
