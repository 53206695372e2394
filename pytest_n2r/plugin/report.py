"""The plugin's reporting half: baselines and CI gating, HTML / JSON reports, JUnit XML properties.

Loaded by :mod:`pytest_n2r.plugin` (``pytest_plugins``), so ``-p no:n2r`` turns it off too. Like the
plugin, it imports only pytest at start-up and does nothing unless one of its options is given (the JUnit
properties ride on relation tests only). Everything it writes comes from plain
:class:`~pytest_n2r.report.RelationRecord` data, gathered from pytest-xdist workers as well, and is written
by the controller process only.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from .options import option, read_options

_RESULT = pytest.StashKey["dict"]()
#: The files to write at the end of the session, by option name (``save_baseline``, ``json``, ``report``).
_OUTPUTS = pytest.StashKey[dict[str, Path]]()
#: The relation test ids this process collected, selected or deselected (for a baseline's ``not_recorded``, and to
#: tell a comparison's deselected relation from a renamed or deleted one).
_COLLECTED = pytest.StashKey[set[str]]()
_OUTPUT_OPTIONS = ("save_baseline", "json", "report")


def _is_worker(config: pytest.Config) -> bool:
    return hasattr(config, "workerinput")


def _tracks_collected(config: pytest.Config) -> bool:
    """Whether this session keeps the relation test ids it collects (:data:`_COLLECTED`)."""
    return config.stash.get(_OUTPUTS, {}).get("save_baseline") is not None or bool(config.getoption("n2r_compare"))


def run_settings(config: pytest.Config) -> dict[str, Any]:
    """What a baseline records of the session that saves it (and a comparison checks against it): pytest's rootdir
    and config file, the render size, the ``--n2r-examples`` default, derandomize and the configured scenes' names
    (those the test ids carry: a ``module:function`` scene's function name, not its loaded scene's name)."""
    from . import session_of
    from .scenes import default_scene_specs

    session = session_of(config)
    settings = session.settings
    return {"rootdir": str(config.rootpath), "config_file": str(config.inipath) if config.inipath else None,
            "size": str(settings.size), "examples": settings.examples, "derandomize": bool(settings.derandomize),
            "scenes": sorted(s.name for s in session.scenes or default_scene_specs())}


def pytest_configure(config: pytest.Config) -> None:
    """Check the reporting options up front: a bad rule, a missing or malformed baseline, or an output path that
    cannot be written (a folder, a folder that is not writable) is a usage error. The baseline is loaded in
    pytest-xdist workers too: they replay its examples."""
    outputs = {name: path for name, path in read_options(config, tuple(option(n) for n in _OUTPUT_OPTIONS)).items()
               if path is not None}
    seen: dict[Path, tuple[str, Path]] = {}
    others = _other_outputs(config) if outputs else []
    for flag, path in [*((option(n).flag, p) for n, p in outputs.items()), *others]:
        # resolved: a/../out.json and out.json (or a link to it) are one file
        other, other_path = seen.setdefault(path.resolve(), (flag, path))
        if other != flag and other.startswith("--n2r-"):  # two other plugins' files: not pytest-n2r's to judge
            both = _one_file(other, other_path, flag, path)
            raise pytest.UsageError(f"pytest-n2r: {both}; give each output its own file (one would replace the other)")
    _check_compare_is_no_report(config, outputs)
    config.stash[_OUTPUTS] = outputs
    if outputs.keys() & {"json", "report"}:  # the previous run's reports are replaced at the first test's start
        from .placeholder import register

        register(config, outputs)
    rules = (option("compare_confidence"), option("compare_fail"), option("compare_fail_on"))
    given = [o.flag for o in rules if o.given(config) is not None]
    if given and not config.getoption("n2r_compare"):
        raise pytest.UsageError(f"pytest-n2r: {given[0]} needs --n2r-compare PATH (the baseline to compare with)")
    if not config.getoption("n2r_compare"):
        return
    values = read_options(config, (*rules, option("compare")))
    config.stash[_RESULT] = {"margin": values["compare_fail"], "confidence": values["compare_confidence"],
                             "fail_on": values["compare_fail_on"], "baseline": values["compare"]}


def _other_outputs(config: pytest.Config) -> list[tuple[str, Path]]:
    """The files other plugins write that a pytest-n2r output must not share: pytest's ``--junitxml`` and
    pytest-html's ``--html``, as they expand them. Checked only when a pytest-n2r output is given."""
    given = [(flag, getattr(config.option, dest, None)) for flag, dest in (("--junitxml", "xmlpath"),
                                                                           ("--html", "htmlpath"))]
    return [(flag, Path(os.path.expanduser(os.path.expandvars(value)))) for flag, value in given
            if isinstance(value, str) and value]


def _check_compare_is_no_report(config: pytest.Config, outputs: dict[str, Path]) -> None:
    """A report written over the baseline this run compares with would replace it (the next comparison fails
    reading a report); ``--n2r-save-baseline`` on it refreshes it in place and is allowed (not after a failing
    gate: see :func:`pytest_sessionfinish`)."""
    compare = _compare_path(config)
    if compare is None:
        return
    for name in ("json", "report"):
        path = outputs.get(name)
        if path is not None and path.resolve() == compare.resolve():
            both = _one_file("--n2r-compare", compare, option(name).flag, path)
            raise pytest.UsageError(f"pytest-n2r: {both}; give the report its own file (it would replace the "
                                    "baseline this run compares with)")


def _compare_path(config: pytest.Config) -> Path | None:
    """The ``--n2r-compare`` file as the baseline is read (``~`` expanded: after ``=`` no shell expands it)."""
    given = config.getoption("n2r_compare")
    return Path(given).expanduser() if given else None


def _one_file(flag_a: str, path_a: Path, flag_b: str, path_b: Path) -> str:
    """Two options naming one file, in words: the same path, or two paths that resolve to one file."""
    if path_a == path_b:
        return f"{flag_a} and {flag_b} are both {path_b}"
    return f"{flag_a} {path_a} and {flag_b} {path_b} are one file ({path_b.resolve()})"


def _relation_ids(items: list[pytest.Item]) -> set[str]:
    from . import RELATION_MARKER

    return {item.nodeid for item in items if item.get_closest_marker(RELATION_MARKER) is not None}


def pytest_deselected(items: list[pytest.Item]) -> None:
    """Remember the deselected relation tests (``-k``, ``-m``, ``--deselect``): a baseline saved from this session
    lists them as not recorded, so a later comparison that runs them says ``missing``, not ``new``."""
    if items and _tracks_collected(items[0].config):
        items[0].config.stash.setdefault(_COLLECTED, set()).update(_relation_ids(items))


def pytest_collection_finish(session: pytest.Session) -> None:
    if _tracks_collected(session.config):
        session.config.stash.setdefault(_COLLECTED, set()).update(_relation_ids(session.items))


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: Any, error: Any) -> None:
    """pytest-xdist's controller collects nothing: it takes the relation tests each worker collected."""
    collected = getattr(node, "workeroutput", {}).get("n2r_collected_relations")
    if collected:
        node.config.stash.setdefault(_COLLECTED, set()).update(collected)


def baseline_examples(config: pytest.Config, nodeid: str, scene: Any, relation: Any) -> list | None:
    """The baseline examples a relation test replays before its search: ``None`` without ``--n2r-compare``,
    for a relation the baseline lacks, or one whose scene content or metric changed (the comparison reports
    those)."""
    baseline = config.stash.get(_RESULT, {}).get("baseline")
    base = baseline.get(nodeid) if baseline else None
    if base is None or base.scene_hash != scene.content_hash or base.metric != repr(relation.metric):
        return None
    from ..report import replay_candidates
    from ..strategies.mutation import is_registered

    candidates = replay_candidates(base)
    unknown = sorted({e.mutation["name"] for e in candidates if e.mutation and not is_registered(e.mutation["name"])})
    if unknown:  # the baseline was read before the tests were imported; now every mutation class is defined
        pytest.fail(f"the baseline's examples of {nodeid} name mutation(s) {unknown} that no imported module "
                    f"defines (renamed or removed since the baseline was saved?); save it again with "
                    f"--n2r-save-baseline", pytrace=False)
    return candidates


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Any:
    """Relation results as JUnit XML properties (``n2r_examples``, ``n2r_inconsistencies``, ...).

    An old-style wrapper, like the plugin's, so pytest 7.4 (the declared minimum) works too."""
    outcome = yield
    plain = getattr(outcome.get_result(), "n2r_record", None)
    if call.when == "call" and plain is not None:
        from ..relation.record import RelationRecord

        record = RelationRecord.from_dict(plain)
        item.user_properties.extend([
            ("n2r_scene", record.scene), ("n2r_metric", record.metric), ("n2r_eps", record.eps),
            ("n2r_examples", len(record.valid_examples)), ("n2r_rejected", record.rejected),
            ("n2r_inconsistencies", record.inconsistencies), ("n2r_worst_deviation", record.worst_deviation),
        ])


def _stopped_early(session: pytest.Session) -> str | None:
    """Why the session did not run every selected test (``-x``, ``--maxfail``, Ctrl-C, ``pytest.exit``), or
    ``None``."""
    if session.exitstatus == pytest.ExitCode.INTERRUPTED:
        return "the session was interrupted"
    why = session.shouldfail or session.shouldstop
    return f"the session stopped early ({why})" if why else None


def _incomplete(session: pytest.Session) -> str | None:
    """Why this session's records do not cover every selected relation test (a partial report), or ``None``."""
    if session.config.option.collectonly:
        return "--collect-only ran no test"
    return _stopped_early(session)


def _baseline_refused(session: pytest.Session, records: list, path: Path) -> str | None:
    """Why the baseline must not be saved from this session (the previous file is then kept), or ``None``."""
    if session.config.option.collectonly:
        return ("--collect-only ran no test, so it would hold no relation (a later --n2r-compare refuses such a "
                "baseline); save it from a session that runs the relation tests")
    stopped = _stopped_early(session)
    if stopped is not None:
        return (f"{stopped}, so it would lack the relations that did not run (a later comparison would pass them as "
                "new); save it from a session that runs to the end (without -x or --maxfail)")
    if not records:
        return ("no relation test ran in this session (none was collected, or every one was deselected with -k / "
                "-m / --deselect or skipped), so it would hold no relation (a later --n2r-compare refuses such a "
                "baseline); save it from a session that runs the relation tests")
    compared = _compare_path(session.config)
    failed = [c for c in session.config.stash.get(_RESULT, {}).get("comparisons") or () if c.fails]
    if failed and compared is not None and compared.resolve() == path.resolve():
        return (f"it is the baseline this run compared with (--n2r-compare), and {len(failed)} relation(s) failed the "
                "comparison: saving would replace it with the regressed run, and the next comparison would pass; "
                "fix the regression, or save the baseline to another file")
    return None


def _comparison_json(config: pytest.Config, result: dict) -> dict[str, Any]:
    """The gate's verdict for the JSON report: its rule, the baseline's ``meta`` (where it came from) and the run's
    settings that differ from it, whether the run passed it, and every relation's outcome."""
    from ..report.baseline import setting_differences

    comparisons = result["comparisons"]
    return {
        "baseline": str(config.getoption("n2r_compare")), "margin": result["margin"],
        "confidence": result["confidence"], "fail_on": list(result["fail_on"]),
        "baseline_meta": result["baseline"].meta,
        "settings_differ": setting_differences(result["baseline"].meta, result.get("settings", {})),
        "passed": not any(c.fails for c in comparisons), "failed": [c.nodeid for c in comparisons if c.fails],
        "relations": [{"nodeid": c.nodeid, "outcome": c.outcome, "also": list(c.also), "verdict": c.verdict,
                       "fails": c.fails, "n": c.n, "mean_change": _number(c.mean_change),
                       "bound": _number(c.bound), "lost": c.lost,
                       "message": c.message, "notes": list(c.notes)} for c in comparisons],
    }


def _number(value: float | None) -> float | None:
    """A comparison's number for the JSON report: ``null`` where it is not finite (no pair: NaN; one pair bounds
    nothing: -Infinity), which no JSON reader but Python's accepts."""
    import math

    return value if value is None or math.isfinite(value) else None


def _images_relative(relation: dict[str, Any], folder: Path) -> dict[str, Any]:
    """``relation`` (a record's dict) with its failure pictures' paths relative to ``folder``, the JSON report's:
    the report and the artifacts folder, downloaded together from CI, still find each other
    (``write_html(..., images_base=<the JSON's folder>)``). A path on another drive stays absolute."""
    from ..data.relative_path import relative_posix

    for example in (relation.get("minimal"), *relation.get("examples", ())):
        for role, path in ((example or {}).get("images") or {}).items():
            example["images"][role] = relative_posix(path, folder)
    return relation


def _why(exc: BaseException) -> str:
    if isinstance(exc, OSError):
        return f"{exc.strerror or exc}" + (f" ({exc.filename})" if exc.filename else "")
    return f"{type(exc).__name__}: {exc}"


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Judge the comparison first (its verdict is the run's, whatever happens to the files), then write each
    output; one that cannot be written (or a baseline :func:`_baseline_refused` refuses: the previous file is
    kept) is reported and fails the run, without hiding the others or the verdict. The reports of a session that
    did not run every selected test are written, marked partial."""
    config = session.config
    outputs = config.stash.get(_OUTPUTS, {})
    if _is_worker(config):
        if _tracks_collected(config):
            collected = config.stash.get(_COLLECTED, set())
            config.workeroutput["n2r_collected_relations"] = sorted(collected)  # type: ignore[attr-defined]  # xdist's
        return
    if not outputs and not config.getoption("n2r_compare"):
        return
    import json

    from ..data.atomic import atomic_write_text
    from ..report import compare_paired, save_baseline
    from ..report.baseline import portable_places
    from ..report.html import write_html
    from . import relation_records

    records = relation_records(config)
    result = config.stash.setdefault(_RESULT, {})
    settings = run_settings(config) if outputs.get("save_baseline") is not None or config.getoption("n2r_compare") \
        else {}
    if config.getoption("n2r_compare") and config.option.collectonly:
        result["skipped"] = "--collect-only ran no test, so nothing was compared with the baseline"
    elif config.getoption("n2r_compare"):
        # in the form a baseline records them: the rootdir from the baseline's folder, the config file from the rootdir
        result["settings"] = portable_places(settings, config.getoption("n2r_compare"))
        # the scene names relation records carry, as the baseline's relations do (not the configured names)
        scenes = {r.scene for r in records if r.scene} or None
        result["comparisons"] = compare_paired(result["baseline"], records, margin=result["margin"],
                                               confidence=result["confidence"], fail_on=result["fail_on"],
                                               collected=config.stash.get(_COLLECTED, set()), scenes=scenes)
        if any(c.fails for c in result["comparisons"]) and session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED
    written, problems = [], []
    path = outputs.get("save_baseline")
    if path is not None and (refused := _baseline_refused(session, records, path)) is not None:
        kept = "; the previous file is left as it was" if path.exists() else ""
        problems.append(f"did not save the baseline {path}: {refused}{kept}")
        path = None
    if path is not None:
        recorded = {r.nodeid for r in records}
        not_recorded = sorted(config.stash.get(_COLLECTED, set()) - recorded)
        meta = {**portable_places(settings, path), **({"not_recorded": not_recorded} if not_recorded else {})}
        writers = [(path, "the baseline", lambda: save_baseline(path, records, meta=meta))]
    else:
        writers = []
    partial = _incomplete(session)
    summary = config.pluginmanager.get_plugin("n2r-summary")
    not_run = summary.not_run() if summary is not None else []
    reruns = summary.reruns if summary is not None else {}  # a record is its test's last try's
    if outputs.get("json") is not None:
        def json_text() -> str:  # NaN where a value is undefined (a rejected example's score): see docs/reporting.md
            payload: dict[str, Any] = {"complete": partial is None}
            if partial is not None:
                payload["incomplete"] = partial
            payload["relations"] = [_images_relative({**r.to_dict(), **({"reruns": reruns[r.nodeid]} if reruns.get(
                r.nodeid) else {})}, outputs["json"].parent) for r in sorted(records, key=lambda r: r.nodeid)]
            payload["not_run"] = not_run
            if result.get("comparisons") is not None:
                payload["comparison"] = _comparison_json(config, result)
            return json.dumps(payload, indent=1, allow_nan=True) + "\n"

        writers.append((outputs["json"], "the JSON results", lambda: atomic_write_text(outputs["json"], json_text())))
    if outputs.get("report") is not None:
        writers.append((outputs["report"], "the HTML report",
                        lambda: write_html(outputs["report"], records, partial=partial, not_run=not_run,
                                           reruns=reruns)))
    for target, what, write in writers:
        try:
            done = write()
            written.append(done if partial is None or what == "the baseline" else f"{done} (partial: {partial})")
        except Exception as exc:  # noqa: BLE001 -- said below; the verdict and the other outputs stand
            problems.append(f"could not write {what} {target}: {_why(exc)}")
    result["written"], result["problems"] = written, problems
    if problems and session.exitstatus == pytest.ExitCode.OK:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    result = config.stash.get(_RESULT, None)
    if not result or _is_worker(config):
        return
    if result.get("skipped"):
        terminalreporter.write_line(f"pytest-n2r baseline {config.getoption('n2r_compare')}: {result['skipped']}")
    comparisons = result.get("comparisons")
    if comparisons is not None:
        from ..report.compare import format_comparison_table, percent

        terminalreporter.section("pytest-n2r baseline comparison")
        from ..report.baseline import describe_baseline, setting_differences

        baseline = result["baseline"]
        terminalreporter.write_line(
            f"baseline {config.getoption('n2r_compare')}: the same examples replayed and paired; a relation is "
            f"worse when the {percent(result['confidence'])} lower bound of the mean increase of the deviation exceeds "
            f"{result['margin']:g}; failing outcomes: {', '.join(result['fail_on'])}"
        )
        terminalreporter.write_line(describe_baseline(baseline.meta))
        differences = setting_differences(baseline.meta, result.get("settings", {}))
        if differences:
            terminalreporter.write_line(
                f"note: this run's settings differ from the baseline's: {'; '.join(differences)}. The replay uses "
                "the baseline's recorded cameras, poses and follow-ups, so each paired example is the baseline's "
                "own; this run's settings apply to its search only (relations of scenes only one side has are "
                "new or missing)", yellow=True)
        if comparisons:
            terminalreporter.write_line(format_comparison_table(comparisons, result["confidence"]))
        else:
            terminalreporter.write_line("no relation ran, nothing compared")
        for c in comparisons:
            if c.message and c.outcome != "ok":
                terminalreporter.write_line(f"{c.nodeid}: {c.outcome}: {c.message}", red=c.fails)
        failed = [c for c in comparisons if c.fails]
        if failed:
            terminalreporter.write_line(
                f"{len(failed)} relation(s) fail the baseline comparison: "
                + ", ".join(f"{c.nodeid} ({c.verdict})" for c in failed), red=True, bold=True)
    for path in result.get("written", []):
        terminalreporter.write_line(f"pytest-n2r wrote {path}")
    for problem in result.get("problems", []):
        terminalreporter.write_line(f"pytest-n2r {problem}", red=True, bold=True)
