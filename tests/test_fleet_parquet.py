"""fleet.parquet built without pandas (imucal.fleet.parquet) is the file pyarrow's Table.from_pylist
writes, byte for byte, for any rows a fleet table holds and for rows it could hold."""
from __future__ import annotations

import io
import math
import struct

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from hypothesis import given, settings
from hypothesis import strategies as st

from imucal.fleet.parquet import arrow_table, json_schema


def _bytes(table) -> bytes:
    buf = io.BytesIO()
    pq.write_table(table, buf)
    return buf.getvalue()


def _same(rows: list[dict], cols: list[str], native: bool = True) -> None:
    """arrow_table's file is from_pylist's; ``native``: built by the JSON reader, not by from_pylist."""
    want = pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows])
    assert (json_schema(rows, cols) == want.schema) if native else json_schema(rows, cols) is None
    got = arrow_table(rows, cols)
    assert got.schema == want.schema
    assert _bytes(got) == _bytes(want)  # the values too (NaN is not equal to itself in Table.equals)


FLOATS = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([-0.0, 5e-324, 1e308, 0.1, math.nan])
TEXT = st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=30) | st.sampled_from(
    ["", "\n", '"', "\\", "a,b", "\u00e9\u4e2d", "\x00"])
COLUMN = st.sampled_from([
    st.none(), st.booleans(), st.integers(-2 ** 63, 2 ** 63 - 1), FLOATS, TEXT,
    st.integers(-10 ** 6, 10 ** 6) | FLOATS,  # ints beside floats: double
])


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_any_typed_columns_match_from_pylist(data):
    n_cols = data.draw(st.integers(1, 6))
    n_rows = data.draw(st.integers(1, 8))
    cols = [f"c{i}" for i in range(n_cols)]
    kinds = [data.draw(COLUMN) for _ in cols]
    rows = [{c: data.draw(st.none() | k) for c, k in zip(cols, kinds)} for _ in range(n_rows)]
    odd_nan = any(isinstance(v, float) and v != v and struct.pack("<d", v) != struct.pack("<d", math.nan)
                  for r in rows for v in r.values())
    _same(rows, cols, native=not odd_nan)


def test_columns_pyarrow_would_type_otherwise_go_the_pyarrow_way():
    """numpy scalars other than float64, and a missing key, give what from_pylist gives."""
    rows = [{"a": np.int32(3), "b": np.float64(0.5), "c": np.bool_(True)}, {"a": None, "b": 1.0}]
    payload = struct.unpack("<d", bytes.fromhex("010000000000f87f"))[0]
    _same([{"a": -math.nan}, {"a": 1.0}], ["a"], native=False)  # a NaN's sign and payload are kept
    _same([{"a": payload}], ["a"], native=False)
    _same(rows, ["a", "b", "c"], native=False)
    _same([{"a": "text", "b": 1.0}, {"a": 2.0, "b": 1}], ["b"])  # only the columns asked for are typed


def test_a_fleet_table_is_written_without_pandas(tmp_path):
    """The batch's own process writes fleet.parquet and never loads pandas (its import was most of a
    batch's fixed cost)."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    code = ("import json, sys\nfrom imucal.fleet.parquet import parquet_writer\n"
            "rows = [{'unit': 'u1', 'status': 'ok', 'outlier': None, 's1': 1.5, 'n': 3, 'skipped': False},\n"
            "        {'unit': 'u2', 'status': 'error', 'outlier': None, 's1': None, 'n': None, 'skipped': True}]\n"
            f"parquet_writer(rows, list(rows[0]))({str(tmp_path / 'f.parquet')!r})\n"
            "print(json.dumps('pandas' in sys.modules))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(root)}, timeout=120)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout) is False
    assert pq.read_table(tmp_path / "f.parquet").to_pylist()[1] == {
        "unit": "u2", "status": "error", "outlier": None, "s1": None, "n": None, "skipped": True}
