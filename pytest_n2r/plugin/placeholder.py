"""Placeholders for the session's reports while it runs: a session that dies without finishing (pytest-timeout's
``thread`` method ends the process with ``os._exit``, a killed CI job) must not leave the previous run's
``--n2r-json`` / ``--n2r-report`` files looking current.

At the first test's start (:func:`pytest_runtest_logstart`, which a pytest-xdist controller gets for its workers'
tests too), the controller replaces each of those files atomically with a placeholder saying the session has not
finished (the JSON ``"complete": false`` with an ``incomplete`` reason and no relation); the session's finish writes the
real report over it (a partial one after an interrupt, as before). Not at configuration: a collection error or a
``--collect-only`` run starts no test, and its finish writes its own report. The baseline
(``--n2r-save-baseline``) gets none: a session that dies keeps the previous baseline, as one stopped early does.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import pytest

__all__ = ["NOT_FINISHED", "Placeholders", "register"]

#: What a placeholder says of its session.
NOT_FINISHED = ("the session that writes this report has not finished: it is still running, or its process ended "
                "without finishing pytest (killed, or pytest-timeout's thread method, which ends it with os._exit)")


class Placeholders:
    """Writes the placeholders of ``outputs`` (``{"json": path, "report": path}``, either may be absent) once, at
    the first test's start. Registered on the controller only (not in pytest-xdist workers)."""

    def __init__(self, outputs: dict[str, Path]):
        self.outputs = {name: path for name, path in outputs.items() if name in ("json", "report")}
        self.written = False

    def pytest_runtest_logstart(self, nodeid: str, location: tuple) -> None:
        if self.written:
            return
        self.written = True
        from ..data.atomic import atomic_write_text

        texts = {"json": json_placeholder, "report": html_placeholder}
        for name, path in self.outputs.items():
            try:
                atomic_write_text(path, texts[name]())
            except OSError:  # the session's finish says why it cannot write this file
                pass


def json_placeholder() -> str:
    """The JSON report of a session that has not finished: no relation, ``complete`` false and why."""
    payload = {"complete": False, "incomplete": NOT_FINISHED, "relations": [], "not_run": []}
    return json.dumps(payload, indent=1) + "\n"


def html_placeholder() -> str:
    """The HTML report of a session that has not finished: a page saying so."""
    return ('<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>pytest-n2r report (not finished)'
            f"</title></head>\n<body><h1>pytest-n2r report: not finished</h1>\n<p>{html.escape(NOT_FINISHED)}.</p>"
            "\n</body></html>\n")


def register(config: pytest.Config, outputs: dict[str, Path]) -> None:
    """Register the placeholders of the session's JSON and HTML reports (the caller has one of them), in the
    controller."""
    if not hasattr(config, "workerinput"):
        config.pluginmanager.register(Placeholders(outputs), "n2r-placeholders")
