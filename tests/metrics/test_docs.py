"""The Python examples of docs/metrics.md and docs/mutations.md run as written (docs cannot drift)."""

from __future__ import annotations

import pytest

from ..conftest import doc_blocks

PAGES = ["metrics.md", "mutations.md"]


@pytest.mark.parametrize("page", PAGES)
def test_page_examples_run(page, capsys):
    blocks = [b.code for b in doc_blocks(page) if b.lang == "python"]
    assert blocks, f"docs/{page} has no python examples"
    for i, code in enumerate(blocks):
        try:
            exec(compile(code, f"docs/{page}[block {i}]", "exec"), {"__name__": f"docs_{i}"})  # noqa: S102
        except Exception as exc:  # noqa: BLE001 - a docs example may raise anything  # pragma: no cover
            pytest.fail(f"docs/{page} python block {i} failed: {exc!r}\n{code}")
