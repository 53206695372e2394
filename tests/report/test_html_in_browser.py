"""The HTML report in a real headless browser: it loads, every image decodes, nothing logs to the console."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import cv2
import numpy as np
import pytest

from pytest_n2r.report import ExampleRecord, RelationRecord
from pytest_n2r.report.html import write_html

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None,
                                reason="Debian's chromium is not installed (apt-get install chromium)")

#: Appended to a copy of the report: after load, the page title becomes each image's decoded width and the
#: number of SVG histograms, so --dump-dom shows what a person would see.
HARNESS = """<script>window.addEventListener("load", () => { document.title = JSON.stringify({
  widths: [...document.images].map(i => i.naturalWidth), svgs: document.querySelectorAll("svg").length }); });
</script>"""


def test_report_renders_in_chromium(tmp_path):
    pictures = {}
    for name, colour in (("source", 60), ("follow-up", 200)):
        pictures[name] = str(tmp_path / f"{name}.png")
        cv2.imwrite(pictures[name], np.full((40, 60, 3), colour, np.uint8))
    minimal = ExampleRecord("wall", "view3", {"yaw": 5.2}, 0.6, 0.4, False, images=pictures)
    good = ExampleRecord("wall", "view3", {"yaw": 1.0}, 0.95, 0.05, True)
    relations = [
        RelationRecord("t.py::test_orb[wall]", "repeatability(px=2.0)", 0.2, [good, minimal], outcome="failed",
                       message="relation violated", minimal=minimal),
        RelationRecord("t.py::test_sift[wall]", "repeatability(px=2.0)", 0.2, [good], outcome="passed"),
    ]
    page = write_html(tmp_path / "report.html", relations)
    harnessed = tmp_path / "harnessed.html"
    harnessed.write_text(page.read_text().replace("</body>", HARNESS + "</body>"))
    result = subprocess.run(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         f"--user-data-dir={tmp_path / 'profile'}", "--enable-logging=stderr", "--v=0",
         "--virtual-time-budget=3000", "--dump-dom", harnessed.as_uri()],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    title = re.search(r"<title>(.*?)</title>", result.stdout, re.DOTALL).group(1)
    seen = json.loads(title.replace("&quot;", '"'))
    assert seen["widths"] == [60, 60], f"every embedded picture must decode (widths {seen['widths']})"
    assert seen["svgs"] == 2, "one histogram per relation"
    console = [line for line in result.stderr.splitlines() if ":CONSOLE" in line]
    assert not console, "the report logged to the browser console:\n" + "\n".join(console)
