"""The studies' checks are study-sized: every test here is marked `study`, so the product's run
(`pytest`, addopts -m 'not study') leaves them to their own step (`pytest -m study`)."""
from __future__ import annotations

from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if HERE in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.study)
