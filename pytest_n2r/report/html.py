"""An HTML report of relation runs (one file: inline CSS, SVG histograms, base64 images; past
:data:`EMBEDDED_IMAGES` pictures, links to the picture files).

Built from plain :class:`~pytest_n2r.relation.record.RelationRecord` data only, so it can be regenerated from
a JSON results file without pytest. Built and written in pieces (:func:`html_chunks`), one picture at a time:
a report of many failing relations at full resolution is hundreds of MiB, and held whole (with its copies while
joined and encoded) took about five times that in memory.
"""

from __future__ import annotations

import base64
import html
import math
import os
import urllib.parse
from collections.abc import Iterator, Mapping
from pathlib import Path

from ..data.atomic import atomic_write_chunks
from ..relation.record import ExampleRecord, RelationRecord

__all__ = ["EMBEDDED_IMAGES", "html_chunks", "render_html", "write_html"]

#: Pictures embedded in a page at most (some 65 KiB each: about 13 MiB); the rest are linked by their path. A
#: regression that broke 1 000 relations made a 348 MB page, which no browser opens, just when it was needed.
EMBEDDED_IMAGES = 200

_CSS = """
.partial{background:#fff8c5;border:1px solid #d4a72c;padding:.5rem}
body{font-family:system-ui,sans-serif;margin:2rem;color:#222;max-width:1200px}
h1{font-size:1.6rem}h2{font-size:1.15rem;margin-top:2rem;border-bottom:1px solid #ddd;padding-bottom:.3rem}
table{border-collapse:collapse;margin:.5rem 0}td,th{border:1px solid #ddd;padding:.25rem .6rem;text-align:right}
th{background:#f4f4f4}td:first-child,th:first-child{text-align:left}
.passed{color:#1a7f37}.failed{color:#cf222e}.skipped{color:#9a6700}
.error{color:#fff;background:#cf222e;font-weight:bold}.xfailed,.xpassed{color:#9a6700}
.not-run{background:#ffebe9;border:1px solid #cf222e;padding:.5rem}
.ex{display:flex;gap:1rem;flex-wrap:wrap;align-items:flex-start}.ex figure{margin:0}
.ex img{max-width:360px;border:1px solid #ccc}figcaption{font-size:.8rem;color:#555}
pre{background:#f6f8fa;padding:.6rem;overflow-x:auto;font-size:.8rem}
"""


def _histogram_svg(deviations: list[float], eps: float, bins: int = 20, width: int = 360, height: int = 120) -> str:
    """An SVG histogram of deviations with the eps threshold as a red line."""
    if not deviations:
        return "<p><em>no valid example</em></p>"
    hi = max(max(deviations), eps) * 1.05 or 1.0
    counts = [0] * bins
    for d in deviations:
        counts[min(bins - 1, int(d / hi * bins))] += 1
    top = max(counts)
    bw = width / bins
    bars = "".join(
        f'<rect x="{i * bw:.1f}" y="{height - 20 - c / top * (height - 30):.1f}" width="{bw - 1:.1f}" '
        f'height="{c / top * (height - 30):.1f}" fill="#4c78a8"><title>{c} example(s) in '
        f'[{i * hi / bins:.3g}, {(i + 1) * hi / bins:.3g})</title></rect>'
        for i, c in enumerate(counts) if c
    )
    x_eps = eps / hi * width
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img" '
        f'aria-label="histogram of deviations">{bars}'
        f'<line x1="{x_eps:.1f}" x2="{x_eps:.1f}" y1="0" y2="{height - 20}" stroke="#cf222e" stroke-width="2"/>'
        f'<text x="{min(x_eps + 3, width - 60):.1f}" y="12" font-size="11" fill="#cf222e">eps={eps:g}</text>'
        f'<text x="0" y="{height - 4}" font-size="11">0</text>'
        f'<text x="{width - 40}" y="{height - 4}" font-size="11">{hi:.3g}</text></svg>'
    )


class _Pictures:
    """The page's pictures: the first ``embed`` embedded, the rest linked (relative to ``page_dir``, the folder of
    the page's file, where there is one; else by absolute ``file:`` URI). ``base``: the folder relative picture
    paths start from (a JSON report's)."""

    def __init__(self, base: Path | None, page_dir: Path | None, embed: int) -> None:
        self.base, self.page_dir, self.left = base, page_dir, embed

    def tag(self, path: str, alt: str) -> str:
        p = Path(path)
        if self.base is not None and not p.is_absolute():  # a JSON report's paths are relative to its folder
            p = self.base / p
        if not p.is_file():
            return f"<p><em>{html.escape(alt)}: image {html.escape(path)} not found</em></p>"
        if self.left <= 0:
            href, where = html.escape(self._href(p)), html.escape(str(p))
            return f'<a href="{href}">{html.escape(alt)} (not embedded: {where})</a>'
        self.left -= 1
        data = base64.b64encode(p.read_bytes()).decode("ascii")
        mime = "image/png" if p.suffix.lower() == ".png" else "image/jpeg"
        return f'<img alt="{html.escape(alt)}" src="data:{mime};base64,{data}">'

    def _href(self, p: Path) -> str:
        absolute = p.absolute()
        if self.page_dir is None:
            return absolute.as_uri()
        try:
            relative = os.path.relpath(absolute, self.page_dir.absolute())
        except ValueError:  # another drive
            return absolute.as_uri()
        return urllib.parse.quote(os.fsencode(Path(relative).as_posix()))  # a name's undecodable bytes as themselves


def _follow_up(ex: ExampleRecord) -> tuple[str, str]:
    """The example's follow-up as (kind, words), the words of failure messages
    (:meth:`~pytest_n2r.strategies.FollowUp.describe`): ``("mutation", "brightness +30 levels (+11.8% of full
    scale)")``, ``("transform", "yaw=+5.250°")`` or ``("transform", "identity")``. A follow-up this process
    cannot rebuild (a mutation class it has not imported, as on a pytest-xdist controller) shows as recorded."""
    kind = "mutation" if ex.mutation is not None else "transform"
    try:
        return kind, ex.follow_up().describe()
    except (ValueError, TypeError):  # InvalidArgument / InvalidType, or a transform with unknown fields
        return kind, repr(ex.mutation if ex.mutation is not None else ex.transform)


def _example_chunks(title: str, ex: ExampleRecord, pictures: _Pictures) -> Iterator[str]:
    """The example's heading and line, then its figures one at a time (each picture read only when asked for)."""
    kind, follow_up = _follow_up(ex)
    yield (f"<h3>{html.escape(title)}</h3><p>scene <code>{html.escape(ex.scene)}</code>, view "
           f"<code>{html.escape(ex.view)}</code>, {kind} <code>{html.escape(follow_up)}</code>: "
           f"score {ex.score:.4g}, deviation {ex.deviation:.4g}</p><div class=\"ex\">")
    for name, path in sorted(ex.images.items()):
        yield f"<figure>{pictures.tag(path, name)}<figcaption>{html.escape(name)}</figcaption></figure>"
    yield "</div>"


def _floor(rel: RelationRecord) -> str:
    """The relation's field floor line (what the scene field alone costs, :mod:`pytest_n2r.relation.floor`), or
    a dash."""
    line = (rel.floor or {}).get("line")
    return html.escape(line) if line else "—"


def _outcome(rel: RelationRecord) -> tuple[str, str]:
    """The relation's outcome as (CSS class, words): pytest's final one where the record has it (``xfailed``,
    ``xpassed``, a strict xfail's pass ``failed``), else the relation's own verdict."""
    shown = rel.pytest_outcome or rel.outcome
    if shown == "failed" and rel.outcome == "passed":
        return shown, "failed (XPASS(strict): the relation held)"
    return shown, shown


def _not_run_table(not_run: list[dict[str, str]]) -> str:
    """A banner and a table of the relation tests that ended without a relation record (pytest's outcome, why)."""
    if not not_run:
        return ""
    rows = "".join(f'<tr><td>{html.escape(t["nodeid"])}</td><td class="{html.escape(t["outcome"])}">'
                   f'{html.escape(t["outcome"])}</td><td>{html.escape(t["reason"])}</td></tr>' for t in not_run)
    return (f'<p class="not-run"><strong>{len(not_run)} relation test(s) did not run their relation</strong> '
            "(an error in a fixture, the test raising or skipping before it returned the system under test, a "
            "skip mark, a crashed worker): they have no section below.</p><table><thead><tr><th>relation test</th>"
            f"<th>outcome</th><th>reason</th></tr></thead><tbody>{rows}</tbody></table>")


def _reruns(count: int) -> str:
    """What a count of earlier tries (pytest-rerunfailures' ``--reruns``) adds to an outcome, or nothing."""
    if not count:
        return ""
    return f" after {'1 earlier try' if count == 1 else f'{count} earlier tries'} under this test id (the last counts)"


def _summary_row(anchor: str, rel: RelationRecord, reruns: int) -> str:
    valid = rel.valid_examples
    rate = rel.inconsistencies / len(valid) if valid else math.nan
    worst = rel.worst
    css, outcome = _outcome(rel)
    return (f'<tr><td><a href="#{anchor}">{html.escape(rel.nodeid)}</a></td><td class="{css}">'
            f"{outcome}{_reruns(reruns)}</td><td>{len(valid)}</td><td>{rel.rejected}</td><td>{rel.undefined}</td>"
            f"<td>{rel.inconsistencies}</td><td>{'—' if math.isnan(rate) else f'{rate:.1%}'}</td>"
            f"<td>{'—' if worst is None else f'{worst.deviation:.4g}'}</td><td>{rel.eps:g}</td>"
            f"<td>{_floor(rel)}</td></tr>")


def _section(anchor: str, rel: RelationRecord, pictures: _Pictures, reruns: int) -> Iterator[str]:
    """The relation's section: heading, line, histogram, then its examples' pictures one at a time."""
    css, outcome = _outcome(rel)
    worst = rel.worst
    timings = ", ".join(f"{k} {v:.2f} s" for k, v in rel.timings.items())
    yield (f'<h2 id="{anchor}">{html.escape(rel.nodeid)}</h2>\n'
           f"<p>metric <code>{html.escape(rel.metric)}</code>, eps {rel.eps:g}, outcome "
           f'<span class="{css}">{outcome}</span>'
           + (f" (the relation's own verdict: {rel.outcome})" if rel.pytest_outcome not in ("", rel.outcome) else "")
           + _reruns(reruns) + (f"; time: {html.escape(timings)}" if timings else "") + "</p>\n"
           + _histogram_svg([e.deviation for e in rel.valid_examples], rel.eps))
    if rel.minimal is not None:
        yield "\n"
        yield from _example_chunks("Failing example (not shrunk: the test is marked xfail)"
                                   if rel.pytest_outcome in ("xfailed", "xpassed")
                                   else "Minimal failing example (shrunk)", rel.minimal, pictures)
    if worst is not None and worst.images and worst is not rel.minimal:
        yield "\n"
        yield from _example_chunks("Worst example", worst, pictures)
    if rel.message:
        yield f"\n<pre>{html.escape(rel.message)}</pre>"


def html_chunks(relations: list[RelationRecord], title: str = "pytest-n2r report", partial: str | None = None,
                not_run: list[dict[str, str]] | None = None, images_base: str | os.PathLike | None = None,
                reruns: Mapping[str, int] | None = None, page_dir: str | os.PathLike | None = None,
                embed: int = EMBEDDED_IMAGES) -> Iterator[str]:
    """The report in pieces, built as they are asked for: the head and the summary table, then each relation's
    section, each picture read and encoded only when its piece is (so one is in memory at a time). Arguments as
    :func:`render_html`'s; ``page_dir``: the folder of the page's file, from which the pictures past the first
    ``embed`` are linked; the pieces joined are its page."""
    pictures = _Pictures(None if images_base is None else Path(images_base),
                         None if page_dir is None else Path(page_dir), embed)
    reruns = reruns or {}
    if partial is not None:
        title = f"{title} (partial)"
    ordered = sorted(relations, key=lambda r: r.nodeid)
    yield (f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
           f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>"
           + ("" if partial is None else f'<p class="partial"><strong>Partial report:</strong> {html.escape(partial)}; '
              "the relations that did not run are not in it.</p>") + _not_run_table(not_run or []) +
           "<table><thead><tr><th>relation</th><th>outcome</th><th>examples</th><th>rejected</th><th>undefined</th>"
           "<th>inconsistencies</th><th>rate</th><th>worst deviation</th><th>eps</th><th>field floor</th></tr>"
           "</thead><tbody>"
           + "".join(_summary_row(f"rel{i}", rel, reruns.get(rel.nodeid, 0)) for i, rel in enumerate(ordered))
           + "</tbody></table>")
    for i, rel in enumerate(ordered):
        if i:
            yield "\n"
        yield from _section(f"rel{i}", rel, pictures, reruns.get(rel.nodeid, 0))
    yield "</body></html>\n"


def render_html(relations: list[RelationRecord], title: str = "pytest-n2r report", partial: str | None = None,
                not_run: list[dict[str, str]] | None = None, images_base: str | os.PathLike | None = None,
                reruns: Mapping[str, int] | None = None, embed: int = EMBEDDED_IMAGES) -> str:
    """The report as one HTML string (:func:`html_chunks` joined); ``partial``: why the session did not run every
    selected relation, shown in the title and a banner under it; ``not_run``: the relation tests that ended without
    a relation record (``{"nodeid", "outcome", "reason"}``, as the JSON report's ``not_run``), in a table above the
    summary; ``images_base``: the folder relative image paths start from (a JSON report's folder: it writes them
    so); ``reruns``: by test id, how many earlier tries of it pytest-rerunfailures ran (the JSON report's ``reruns``),
    said beside its outcome; ``embed``: how many pictures are embedded at most, the rest linked by absolute
    ``file:`` URI."""
    return "".join(html_chunks(relations, title, partial, not_run, images_base, reruns, embed=embed))


def write_html(path: str | os.PathLike, relations: list[RelationRecord], title: str = "pytest-n2r report",
               partial: str | None = None, not_run: list[dict[str, str]] | None = None,
               images_base: str | os.PathLike | None = None, reruns: Mapping[str, int] | None = None,
               embed: int = EMBEDDED_IMAGES) -> Path:
    """Write the report to ``path`` atomically, piece by piece as :func:`html_chunks` builds it (one picture in
    memory at a time, never the whole page); the file is :func:`render_html`'s page, but for the pictures past the
    first ``embed``, linked relative to its folder."""
    return atomic_write_chunks(path, html_chunks(relations, title, partial, not_run, images_base, reruns,
                                                 page_dir=Path(path).parent, embed=embed))
