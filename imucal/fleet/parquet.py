"""fleet.parquet: the fleet table in Parquet, built without pandas.

pyarrow makes arrays of Python values (``pa.array``, ``Table.from_pylist``) through its pandas shim,
which imports pandas (about 0.25 s of CPU, the largest part of a batch's fixed cost: issue 30) only to
ask whether a value is a pandas object. Here the table is read by pyarrow's JSON reader (C++, no
pandas) from newline-delimited JSON under an explicit schema: each column's type the one
``Table.from_pylist`` infers from its values (null, bool, int64, double or string), the values
exact (JSON writes a float's shortest repr, infinities and the canonical NaN included; null stays
apart from ""). A column whose values ``from_pylist`` would type or store otherwise (numpy scalars,
text beside numbers, a NaN with a sign or payload, ...) sends the whole table the pyarrow way, which
gives what it always gave.
"""
from __future__ import annotations

import io
import json
import math
import struct
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

#: The type ``Table.from_pylist`` infers for a column holding these Python types (None aside).
_TYPES = {frozenset(): "null", frozenset({bool}): "bool_", frozenset({int}): "int64",
          frozenset({float}): "float64", frozenset({int, float}): "float64", frozenset({str}): "string"}


#: The NaN JSON reads back (the sign and payload of any other NaN are not carried by JSON's NaN).
_NAN_BITS = struct.pack("<d", math.nan)


def _kind(v: Any) -> type:
    """bool, int, float or str for exactly those Python types (and numpy's float64, a float), else object
    (a NaN other than the canonical one too: from_pylist keeps its bits)."""
    t = type(v)
    if t in (bool, int, str):
        return t
    if isinstance(v, float):
        return float if v == v or struct.pack("<d", v) == _NAN_BITS else object
    return object


def json_schema(rows: Sequence[Mapping[str, Any]], cols: Sequence[str]) -> Any:
    """The schema ``Table.from_pylist`` infers for ``rows``, when every column holds values of one of
    the types above; None when it would type them otherwise (or there are no rows)."""
    import pyarrow as pa

    kinds = [frozenset(_kind(r.get(c)) for r in rows if r.get(c) is not None) for c in cols]
    if not rows or any(k not in _TYPES for k in kinds):
        return None
    return pa.schema([(c, getattr(pa, _TYPES[k])()) for c, k in zip(cols, kinds)])


def arrow_table(rows: Sequence[Mapping[str, Any]], cols: Sequence[str]) -> Any:
    """The pyarrow Table ``Table.from_pylist`` makes of ``rows`` (each row's values of ``cols``)."""
    import pyarrow as pa

    schema = json_schema(rows, cols)
    if schema is None:
        return pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows])
    import pyarrow.json as pj

    text = "\n".join(json.dumps({c: r.get(c) for c in cols}) for r in rows).encode()
    return pj.read_json(io.BytesIO(text), read_options=pj.ReadOptions(block_size=max(len(text), 1 << 20)),
                        parse_options=pj.ParseOptions(explicit_schema=schema, unexpected_field_behavior="error"))


def parquet_writer(rows: Sequence[Mapping[str, Any]], cols: Sequence[str]) -> Callable[[Path], None] | None:
    """A writer of the rows to a Parquet file when pyarrow is importable, else None."""
    try:
        import pyarrow.parquet as pq
    except ImportError:
        return None

    def write(path: Path) -> None:
        pq.write_table(arrow_table(rows, cols), str(path))

    return write
