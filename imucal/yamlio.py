"""Reading YAML files with one-line errors (file, field, fix); ``yaml.safe_load`` only."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from .errors import ImucalError


def read_yaml(path: str | os.PathLike, field: str, fix: str) -> Any:
    """Parse the YAML file at ``path``; any failure is an ImucalError naming it and ``field``."""
    import yaml

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ImucalError("file not found", file=str(p), field=field, fix=fix) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ImucalError(f"cannot read: {exc}", file=str(p), field=field) from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise ImucalError(f"is not valid YAML{where}", file=str(p), field=field,
                          fix="check indentation and quoting") from None
    except (ValueError, TypeError, RecursionError) as exc:  # tags that fail, e.g. "!!timestamp 2001-02-30"
        raise ImucalError(f"is not valid YAML ({type(exc).__name__}: {exc})", file=str(p), field=field,
                          fix="check indentation and quoting") from None
