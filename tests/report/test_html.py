"""The HTML report is one self-contained file built from plain records."""

from __future__ import annotations

import base64
import html
import os
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from pytest_n2r.report import ExampleRecord, RelationRecord
from pytest_n2r.report.html import render_html, write_html


def _failing_relation(tmp_path):
    img = tmp_path / "follow.png"
    cv2.imwrite(str(img), np.full((8, 8, 3), 200, np.uint8))
    minimal = ExampleRecord("wall", "view3", {"yaw": 5.25}, 0.7, 0.3, False, images={"follow-up": str(img)})
    ok = ExampleRecord("wall", "view3", {"yaw": 1.0}, 0.95, 0.05, True)
    rejected = ExampleRecord("wall", "view3", {"yaw": 80.0}, float("nan"), float("nan"), False, status="rejected",
                             reason="outside the field")
    undefined = ExampleRecord("wall", "view1", {"yaw": 2.0}, float("nan"), float("nan"), False, status="undefined",
                              reason="the SUT found no keypoint in either view")
    return RelationRecord("test_x.py::test_orb[wall]", "repeatability(px=2.0)", 0.2, [ok, minimal, rejected, undefined],
                          outcome="failed", message="boom <b>", timings={"render": 1.5}, minimal=minimal)


def test_report_shows_counts_histogram_and_embedded_images(tmp_path):
    page = render_html([_failing_relation(tmp_path)])
    row = re.search(r"<tr><td><a href=\"#rel0\">.*?</tr>", page).group(0)
    cells = re.findall(r"<td[^>]*>(.*?)</td>", row)
    # examples (accepted), rejected, undefined, inconsistencies, rate, worst, eps, field floor (none measured)
    assert cells[1:] == ["failed", "2", "1", "1", "1", "50.0%", "0.3", "0.2", "—"], cells
    rel = _failing_relation(tmp_path)
    rel.floor = {"line": "field floor 0.125 (photo vs field render)", "below_floor": False}
    assert "<td>field floor 0.125 (photo vs field render)</td></tr>" in render_html([rel]), \
        "a measured field floor is shown beside the relation"
    assert "<svg" in page and 'aria-label="histogram of deviations"' in page
    assert "data:image/png;base64," in page, "artifact images must be embedded, not linked"
    assert "boom &lt;b&gt;" in page, "messages must be escaped"
    assert "Minimal failing example" in page
    words = rel.minimal.follow_up().describe()  # the words failure messages use, translation units included
    assert words == "yaw=+5.250°"
    assert f"transform <code>{html.escape(words)}</code>" in page, "the minimal example's transform is not shown"


def test_missing_image_is_reported_not_fatal(tmp_path):
    rel = _failing_relation(tmp_path)
    rel.minimal.images["source"] = str(tmp_path / "gone.png")
    assert "image " + str(tmp_path / "gone.png") + " not found" in render_html([rel])


def test_write_html_is_atomic(tmp_path):
    out = write_html(tmp_path / "r" / "report.html", [_failing_relation(tmp_path)])
    assert out.read_text().startswith("<!DOCTYPE html>")
    assert sorted(p.name for p in out.parent.iterdir()) == ["report.html"]


def test_a_mutation_example_shows_its_mutation(tmp_path):
    """A mutation relation's examples have no transform (``transform=None``): the report names the mutation."""
    minimal = ExampleRecord("wall", "view3", None, 0.7, 0.3, False, mutation={"name": "brightness", "levels": 30})
    rel = RelationRecord("test_x.py::test_bright[wall]", "repeatability(px=2.0)", 0.2, [minimal], outcome="failed",
                         minimal=minimal)
    page = render_html([rel])
    words = minimal.follow_up().describe()  # the words failure messages use
    assert words == "brightness +30 levels (+11.8% of full scale)"
    assert f"mutation <code>{html.escape(words)}</code>" in page, "the minimal example's mutation is not shown"
    assert "transform <code>" not in page, "a mutation example was described as a pose transform"


def test_a_follow_up_that_cannot_be_rebuilt_is_shown_as_recorded(tmp_path):
    """A mutation class this process has not imported (a pytest-xdist controller) does not stop the report."""
    minimal = ExampleRecord("wall", "view3", None, 0.7, 0.3, False, mutation={"name": "not_imported", "k": 1})
    rel = RelationRecord("test_x.py::test_mine[wall]", "repeatability(px=2.0)", 0.2, [minimal], outcome="failed",
                         minimal=minimal)
    assert f"mutation <code>{html.escape(repr(minimal.mutation))}</code>" in render_html([rel])


def test_small_deviations_are_shown_as_the_terminal_shows_them(tmp_path):
    """A deviation of 1.04e-07 failing eps 1e-08 was shown 0.0000 (``:.4f``), as if it had passed with room."""
    tiny = ExampleRecord("wall", "view3", {"yaw": 5.0}, 1.04e-07, 1.04e-07, False)
    rel = RelationRecord("test_x.py::test_tiny[wall]", "abs", 1e-08, [tiny], outcome="failed", minimal=tiny)
    page = render_html([rel])
    row = re.search(r"<tr><td><a href=\"#rel0\">.*?</tr>", page).group(0)
    assert "<td>1.04e-07</td>" in row, f"the worst deviation is not shown as the terminal shows it: {row}"
    assert "score 1.04e-07, deviation 1.04e-07" in page, "the minimal example's numbers lost their digits"
    assert "0.0000" not in page


def test_errors_have_a_style():
    """``class="error"`` (a relation that errored, a relation test whose fixture failed) had no CSS: plain black."""
    rel = RelationRecord("test_x.py::test_err[wall]", "abs", 0.1, [], outcome="error", message="boom")
    page = render_html([rel])
    assert 'class="error"' in page
    assert re.search(r"(^|[},\s])\.error\s*\{[^}]*color", page, re.MULTILINE), "class=\"error\" has no style"


def _report_cases(folder):
    """Relations that use every part of the page (the banners, the not-run table, a strict XPASS, an xfail, an
    error, a floor, timings, a minimal and a distinct worst example, an embedded PNG and JPEG, a missing picture),
    with fixed picture bytes so that the page is the same on every machine (the pictures are embedded, not
    decoded)."""
    (folder / "a.png").write_bytes(bytes(range(256)) * 3)
    (folder / "b.JPG").write_bytes(b"\xff\xd8 a jpeg's first bytes")
    pictures = {"source": str(folder / "a.png"), "follow-up": "b.JPG", "diff": "gone.png"}
    minimal = ExampleRecord("wall", "view3", {"yaw": 5.25}, 0.7, 0.3, False, images=pictures)
    worst = ExampleRecord("wall", "view1", {"yaw": -7.5, "x": 0.125}, 0.2, 0.8, False, images={"source": "a.png"})
    ok = ExampleRecord("wall", "view3", {"yaw": 1.0}, 0.95, 0.05, True)
    rejected = ExampleRecord("wall", "view3", {"yaw": 80.0}, float("nan"), float("nan"), False, status="rejected",
                             reason="outside the field")
    bright = ExampleRecord("lab", "v0", None, 0.6, 0.4, False, mutation={"name": "brightness", "levels": 30},
                           images={"follow-up": "a.png"})
    return [
        RelationRecord("test_b.py::test_orb[wall]", "repeatability(px=2.0)", 0.2, [ok, minimal, worst, rejected],
                       outcome="failed", message="boom <b> & \"quotes\"", timings={"render": 1.5, "sut": 0.25},
                       minimal=minimal, floor={"line": "field floor 0.125 (photo <vs> field render)"}),
        RelationRecord("test_a.py::test_bright[lab]", "abs", 1e-08, [bright], outcome="failed",
                       pytest_outcome="xfailed", minimal=bright),
        RelationRecord("test_c.py::test_held[wall]", "abs", 0.5, [ok], outcome="passed", pytest_outcome="failed"),
        RelationRecord("test_d.py::test_none[wall]", "abs", 0.5, [rejected], outcome="passed"),
        RelationRecord("test_e.py::test_err[wall]", "abs", 0.1, [], outcome="error", message="Traceback\n  <boom>"),
    ]


@pytest.mark.parametrize("kwargs", [{"title": "n2r <&> report", "partial": "stopped after 1 failure (-x)",
                                      "not_run": [{"nodeid": "t.py::test_f[<x>]", "outcome": "error",
                                                   "reason": "fixture 'sut'"}]}, {}], ids=["full", "plain"])
def test_the_file_written_in_pieces_is_the_page(tmp_path, kwargs):
    """``write_html`` writes the page in pieces as they are built; the file is ``render_html``'s page to the byte
    (when the pieces came in, 7 December, both were compared with the page the report wrote whole before: the
    same bytes)."""
    kwargs = {**kwargs, "images_base": tmp_path}
    page = render_html(_report_cases(tmp_path), **kwargs).encode("utf-8")
    assert page.count(b"data:image/") == 4, "the cases name four pictures that exist: each must be embedded"
    out = write_html(tmp_path / "out" / "report.html", _report_cases(tmp_path), **kwargs)
    assert out.read_bytes() == page, "the file written in pieces differs from the page"


def test_write_html_reads_a_relations_pictures_only_after_writing_the_relation_before(tmp_path, monkeypatch):
    """The report is written as it is built: the next relation's pictures are read after the previous relation's
    section is in the file, so one relation's pictures at a time are in memory (a page of many failing relations
    at full resolution held whole took about five times its size)."""
    for name in ("first", "second"):
        (tmp_path / f"{name}.png").write_bytes(name.encode() * 100)
    relations = []
    for name in ("first", "second"):
        ex = ExampleRecord("wall", "v", {"yaw": 1.0}, 0.5, 0.5, False, images={"source": str(tmp_path / f"{name}.png")})
        relations.append(RelationRecord(f"t.py::test_{name}", "abs", 0.1, [ex], outcome="failed", minimal=ex))
    events = []
    read_bytes = Path.read_bytes

    def recorded_read(self):
        events.append(f"read {self.name}")
        return read_bytes(self)

    class RecordedFile:
        def __init__(self, fh):
            self._fh = fh

        def __getattr__(self, name):
            return getattr(self._fh, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return self._fh.__exit__(*exc)

        def write(self, data):
            for name in ("first", "second"):
                if base64.b64encode(name.encode() * 100) in data:
                    events.append(f"write {name}.png")
            return self._fh.write(data)

        def writelines(self, lines):
            for data in lines:
                self.write(data)

    fdopen = os.fdopen
    monkeypatch.setattr(Path, "read_bytes", recorded_read)
    monkeypatch.setattr(os, "fdopen", lambda *args, **kwargs: RecordedFile(fdopen(*args, **kwargs)))
    out = write_html(tmp_path / "report.html", relations)
    assert events == ["read first.png", "write first.png", "read second.png", "write second.png"], \
        f"the report was not written as it was built: {events}"
    assert out.read_text() == render_html(relations)


def test_pictures_past_the_budget_are_linked_so_a_large_regression_still_opens(tmp_path):
    """1 000 failing relations, every picture embedded, made a 348 MB page no browser opens; past the budget the
    pictures are linked by their path, relative to the page's folder."""
    from pytest_n2r.report.html import EMBEDDED_IMAGES

    pictures = tmp_path / "artifacts" / "é x"
    pictures.mkdir(parents=True)
    relations = []
    for i in range(3):
        rel = _failing_relation(pictures)
        rel.nodeid = f"test_x.py::test_orb[{i}]"
        relations.append(rel)
    page = write_html(tmp_path / "out" / "report.html", relations, embed=2).read_text()
    assert page.count("data:image/png;base64,") == 2, "not the first 2 pictures embedded"
    assert page.count('<a href="../artifacts/%C3%A9%20x/follow.png">follow-up (not embedded: ') == 1, \
        "the third picture is not linked relative to the page's folder"
    assert EMBEDDED_IMAGES >= 100 and render_html(relations).count("data:image/png;base64,") == 3


def test_a_linked_picture_whose_name_is_not_text_keeps_its_bytes(tmp_path):
    """A folder name no encoding decodes (Python holds its bytes as lone surrogates): quoting it failed and the
    link fell back to an absolute file: URI, which breaks when the report is moved."""
    made = tmp_path / "made"
    made.mkdir()
    rel = _failing_relation(made)  # OpenCV cannot write under such a name (it crashes): made under another
    pictures = tmp_path / os.fsdecode(b"caf\xff")
    made.rename(pictures)
    rel.minimal.images = {name: str(pictures / Path(path).name) for name, path in rel.minimal.images.items()}
    page = write_html(tmp_path / "report.html", [rel], embed=0).read_text(errors="replace")
    assert '<a href="caf%FF/follow.png">' in page, "the picture is not linked relative to the page by its bytes"
