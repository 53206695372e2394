"""The Python examples of docs/metrics.md and docs/mutations.md run as written (docs cannot drift)."""

from __future__ import annotations

import re

import pytest

from ..conftest import REPO_ROOT

PAGES = ["metrics.md", "mutations.md"]


def python_blocks(page: str) -> list[str]:
    text = (REPO_ROOT / "docs" / page).read_text(encoding="utf-8")
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


@pytest.mark.parametrize("page", PAGES)
def test_page_examples_run(page, capsys):
    blocks = python_blocks(page)
    assert blocks, f"docs/{page} has no python examples"
    for i, code in enumerate(blocks):
        try:
            exec(compile(code, f"docs/{page}[block {i}]", "exec"), {"__name__": f"docs_{i}"})  # noqa: S102
        except Exception as exc:  # pragma: no cover - the message is the point
            pytest.fail(f"docs/{page} python block {i} failed: {exc!r}\n{code}")
