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
            # dont_inherit: a block runs as a file of its own would (without this module's __future__ imports)
            exec(compile(code, f"docs/{page}[block {i}]", "exec", dont_inherit=True),  # noqa: S102
                 {"__name__": f"docs_{i}"})
        except Exception as exc:  # noqa: BLE001 - a docs example may raise anything  # pragma: no cover
            pytest.fail(f"docs/{page} python block {i} failed: {exc!r}\n{code}")
