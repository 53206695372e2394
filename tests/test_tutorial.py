"""docs/tutorial.md, followed as a reader would: its files are written into a fresh project (pytester), its
commands run there in page order, and what each run prints is checked against the output the page shows.

A block with ``title="PATH"`` is a file of the reader's project (a later block with the same title replaces
it, as the reader edits the file); a ``bash`` block holds commands; a ``text`` block after a command is its
output, abridged by leaving lines out (``...``) but never by changing a line; a ``yaml`` block is a CI step
whose commands must be ones the page ran. Each shown line must match a line of the real output with its
numbers free; then, when the reader's project derandomizes its runs (``n2r_derandomize``, which the page says
makes the runs show its numbers), the numbers must be the ones shown too (the minimal transform, the example,
inconsistent, rejected, shrink-step, render and SUT-call counts, the scores), except times (a number
followed by ``s``) and the durations of pytest's summary line, which is compared by its outcome counts. A
count the prose quotes in backticks (`0 renders`) must be in the output shown above it.
"""

from __future__ import annotations

import re
import shlex
from importlib import metadata
from pathlib import Path

import pytest
from packaging.version import Version

from .conftest import _FENCE, REPO_ROOT, DocBlock, doc_blocks

PAGE = "tutorial.md"
_NUMBER = r"[-+]?\d+(?:\.\d+)?"
_OUTCOME = re.compile(r"(\d+) (passed|failed|errors?|skipped|xfailed|xpassed)")
_QUOTED = re.compile(r"`(\d+ [A-Za-z][^`]*)`")  # `0 renders`: the prose quoting a run's output
_PYTEST = ["python", "-m", "pytest"]
_PIP_INSTALL = ["python", "-m", "pip", "install"]
_TIME = re.compile(_NUMBER + r"(?= ?s\b)")  # "4.05 s", "in 5.63s": a time, never the same twice
_DERANDOMIZED = re.compile(r"""^\s*n2r_derandomize\s*=\s*(?:["']?yes["']?|true|["']true["'])\s*$""", re.MULTILINE)

pytestmark = pytest.mark.slow


def _line_pattern(line: str) -> str:
    """A shown output line as a regular expression: the line verbatim, except that any number is free and
    runs of spaces, ``=`` or ``_`` (padding that depends on the terminal width) have any length."""
    def literal(text: str) -> str:
        return "".join(re.escape(c) if c not in " =_" else c for c in text)

    pattern = _NUMBER.join(literal(p) for p in re.split(_NUMBER, line.rstrip()))
    pattern = re.sub(r" {2,}", r" +", re.sub(r"={3,}", r"=+", re.sub(r"_{3,}", r"_+", pattern)))
    return r"^" + pattern + r"$"


def _figures(line: str) -> list[re.Match[str]]:
    """The numbers of an output line that a derandomized run reproduces: all but its times."""
    times = {m.start() for m in _TIME.finditer(line)}
    return [m for m in re.finditer(_NUMBER, line) if m.start() not in times]


def _in_context(line: str, match: re.Match[str]) -> str:
    """``match`` with the words around it, to say which number of ``line`` differs."""
    return ("..." if match.start() > 30 else "") + line[max(0, match.start() - 30):match.end() + 30].strip() + \
        ("..." if match.end() + 30 < len(line) else "")


def _match_in_order(patterns: list[str], lines: list[str]) -> list[int] | int:
    """The index of the line each pattern matches, each after the previous one (lines between are skipped,
    as ``re_match_lines(consecutive=False)`` does), or the index of the first pattern that matches none."""
    found: list[int] = []
    at = 0
    for i, pattern in enumerate(patterns):
        while at < len(lines) and not re.match(pattern, lines[at]):
            at += 1
        if at == len(lines):
            return i
        found.append(at)
        at += 1
    return found


def _derandomized(project: Path, command: str) -> bool:
    """Whether the run of ``command`` in ``project`` derandomizes (the page's claim that it shows its numbers)."""
    pyproject = project / "pyproject.toml"
    in_ini = pyproject.is_file() and _DERANDOMIZED.search(pyproject.read_text(encoding="utf-8")) is not None
    flag = re.search(r"--n2r-derandomize[ =](\S+)", command)
    return flag.group(1) in ("yes", "true") if flag else in_ini


def _outcomes(text: str) -> dict[str, int]:
    """``{"failed": 1, ...}`` from a pytest summary line (``errors`` counted as ``error``)."""
    return {kind.rstrip("s") if kind.startswith("error") else kind: int(n) for n, kind in _OUTCOME.findall(text)}


def _check_installed(args: list[str], where: str) -> None:
    """Each requirement of a ``pip install`` line is installed here (a pinned one at that version)."""
    for arg in args:
        if arg.startswith("-"):
            continue
        name, _, pinned = arg.partition("==")
        name = Path(name).name if "/" in name else name
        try:
            installed = metadata.version(name)
        except metadata.PackageNotFoundError:
            pytest.fail(f"{where}: the page installs {arg!r}, but no distribution {name!r} is installed here")
        if pinned:
            assert Version(installed).public == Version(pinned).public, (
                f"{where}: the page pins {name}=={pinned}; the test environment has {installed}"
            )


def _check_output(block: DocBlock, result: pytest.RunResult | None, command: str | None, project: Path,
                  where: str) -> None:
    """The output ``block`` shows against the run ``result`` of ``command`` in ``project``: the same outcome
    counts, every shown line in the real output in the same order, every shown picture written."""
    assert result is not None, f"{where}: an output block with no command before it"
    shown = [line for line in block.code.splitlines() if line.strip() and line.strip() != "..."]
    actual = result.outlines
    summary = [line for line in shown if line.startswith("=") and _OUTCOME.search(line)]
    shown = [line for line in shown if line not in summary]  # compared by outcome (durations vary in form)
    assert summary, f"{where}: the output of `{command}` shown on the page ends without pytest's summary line"
    real = _outcomes(result.outlines[-1] if result.outlines else "")
    assert _outcomes(summary[-1]) == real, (
        f"{where}: the page says `{command}` ends with {summary[-1]!r}, but it ended with "
        f"{result.outlines[-1] if result.outlines else '(no output)'!r}\n" + "\n".join(actual)
    )
    matched = _match_in_order([_line_pattern(line) for line in shown], actual)
    if isinstance(matched, int):  # in order; lines of the real output the page leaves out are skipped
        pytest.fail(f"{where}: the output of `{command}` shown on the page differs from the real output: no line "
                    f"after the ones before it matches {shown[matched]!r}; real output:\n" + "\n".join(actual),
                    pytrace=False)
    if _derandomized(project, command or ""):  # the page says these runs show its numbers: they must
        differ = [
            f"the page shows {on_page.group()} in {_in_context(line, on_page)!r}; the run printed "
            f"{in_run.group()}: {_in_context(actual[index], in_run)!r}"
            for line, index in zip(shown, matched)
            for on_page, in_run in zip(_figures(line), _figures(actual[index]))
            if on_page.group() != in_run.group()
        ]
        if differ:
            pytest.fail(f"{where}: the derandomized run of `{command}` printed other numbers than the page "
                        "shows:\n  " + "\n  ".join(differ) + "\nreal output:\n" + "\n".join(actual), pytrace=False)
    for picture in re.findall(r"(\S+/\S+\.png)", block.code):  # paths, not view names
        assert (project / picture).is_file(), f"{where}: the page shows {picture}, which the run did not write"


def test_every_block_of_the_tutorial_runs_as_shown(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.delenv("CI", raising=False)  # the page's settings alone decide derandomization
    monkeypatch.delenv("PYTEST_ADDOPTS", raising=False)
    monkeypatch.setenv("PYTHONPATH", str(REPO_ROOT))  # the reader's pytest runs this checkout's pytest-n2r
    blocks = doc_blocks(PAGE)
    assert blocks, f"docs/{PAGE} has no code blocks"
    result: pytest.RunResult | None = None
    command: str | None = None
    ran: list[str] = []
    for block in blocks:
        where = f"docs/{PAGE}:{block.line}"
        if block.title:
            path = pytester.path / block.title
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(block.code, encoding="utf-8")
        elif block.lang == "bash":
            for line in filter(None, (ln.strip() for ln in block.code.splitlines())):
                args = shlex.split(line)
                if args[:4] == _PIP_INSTALL:
                    _check_installed(args[4:], where)
                elif args[:3] == _PYTEST:
                    result, command = pytester.runpytest_subprocess(*args[3:]), line
                    ran.append(line)
                else:
                    pytest.fail(f"{where}: no test runs the command {line!r}; use `python -m pytest ...` or "
                                "`python -m pip install ...`, or teach tests/test_tutorial.py to run it")
        elif block.lang == "text":
            _check_output(block, result, command, pytester.path, where)
        elif block.lang == "yaml":
            steps = re.findall(r"^\s*run:\s*(.+)$", block.code, flags=re.MULTILINE)
            assert steps, f"{where}: a yaml block without a `run:` step"
            unknown = [step for step in steps if step.strip() not in ran]
            assert not unknown, f"{where}: CI steps {unknown} are not commands the tutorial ran ({ran})"
        else:
            pytest.fail(f"{where}: a {block.lang or 'plain'!r} block with no title: the test cannot run it")
    assert ran, f"docs/{PAGE} runs no pytest command"


def test_the_prose_quotes_the_output_shown_before_it():
    """A count the prose quotes (`0 renders`) is in the output block above it, which the run checks."""
    text = (REPO_ROOT / "docs" / PAGE).read_text(encoding="utf-8")
    shown, at = "", 0
    for fence in [*_FENCE.finditer(text), None]:
        prose = text[at:fence.start() if fence else len(text)]
        for quote in _QUOTED.finditer(prose):
            line = text.count("\n", 0, at + quote.start()) + 1
            pattern = ".*".join(re.escape(part.strip()) for part in quote[1].split("..."))
            assert shown and re.search(pattern, shown), (
                f"docs/{PAGE}:{line}: the prose quotes `{quote[1]}`, which the output shown above it does not print"
            )
        if fence:
            shown, at = (fence[3] if fence[1] == "text" else shown), fence.end()


def test_the_tutorial_is_in_the_nav_and_linked_from_the_home_page():
    assert f": {PAGE}" in (REPO_ROOT / "mkdocs.yml").read_text(encoding="utf-8"), \
        f"docs/{PAGE} is not in the mkdocs nav"
    assert f"({PAGE})" in (REPO_ROOT / "docs" / "index.md").read_text(encoding="utf-8"), \
        f"docs/index.md does not link to {PAGE}"
