"""The plugin's reporting half: baselines and CI gating, HTML / JSON reports, JUnit XML properties.

Loaded by :mod:`pytest_n2r.plugin` (``pytest_plugins``), so ``-p no:n2r`` turns it off too. Like the
plugin, it imports only pytest at start-up and does nothing unless one of its options is given (the JUnit
properties ride on relation tests only). Everything it writes comes from plain
:class:`~pytest_n2r.report.RelationRecord` data, gathered from pytest-xdist workers as well, and is written
by the controller process only.
"""

from __future__ import annotations

from typing import Any

import pytest

from .options import option, read_options

_RESULT = pytest.StashKey["dict"]()


def _is_worker(config: pytest.Config) -> bool:
    return hasattr(config, "workerinput")


def pytest_configure(config: pytest.Config) -> None:
    """Check the reporting options up front: a bad rule or a missing or malformed baseline is a usage
    error. The baseline is loaded in pytest-xdist workers too: they replay its examples."""
    rules = (option("compare_confidence"), option("compare_fail"), option("compare_fail_on"))
    given = [o.flag for o in rules if o.given(config) is not None]
    if given and not config.getoption("n2r_compare"):
        raise pytest.UsageError(f"pytest-n2r: {given[0]} needs --n2r-compare PATH (the baseline to compare with)")
    if not config.getoption("n2r_compare"):
        return
    values = read_options(config, (*rules, option("compare")))
    config.stash[_RESULT] = {"margin": values["compare_fail"], "confidence": values["compare_confidence"],
                             "fail_on": values["compare_fail_on"], "baseline": values["compare"]}


def baseline_examples(config: pytest.Config, nodeid: str, scene: Any, relation: Any) -> list | None:
    """The baseline examples a relation test replays before its search: ``None`` without ``--n2r-compare``,
    for a relation the baseline lacks, or one whose scene content or metric changed (the comparison reports
    those)."""
    baseline = config.stash.get(_RESULT, {}).get("baseline")
    base = baseline.get(nodeid) if baseline else None
    if base is None or base.scene_hash != scene.content_hash or base.metric != repr(relation.metric):
        return None
    from ..report import replay_candidates

    return replay_candidates(base)


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


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    config = session.config
    if _is_worker(config):
        return
    options = {name: config.getoption(name) for name in ("n2r_save_baseline", "n2r_compare", "n2r_report", "n2r_json")}
    if not any(options.values()):
        return
    import json

    from ..data.atomic import atomic_write_text
    from ..report import compare_paired, save_baseline
    from ..report.html import write_html
    from . import relation_records

    records = relation_records(config)
    written = []
    if options["n2r_save_baseline"]:
        written.append(save_baseline(options["n2r_save_baseline"], records))
    if options["n2r_json"]:
        payload = {"relations": [r.to_dict() for r in sorted(records, key=lambda r: r.nodeid)]}
        written.append(atomic_write_text(options["n2r_json"], json.dumps(payload, indent=1, allow_nan=True) + "\n"))
    if options["n2r_report"]:
        written.append(write_html(options["n2r_report"], records))
    result = config.stash.get(_RESULT, {})
    result["written"] = written
    config.stash[_RESULT] = result
    if options["n2r_compare"]:
        result["comparisons"] = compare_paired(result["baseline"], records, margin=result["margin"],
                                               confidence=result["confidence"], fail_on=result["fail_on"])
        if any(c.fails for c in result["comparisons"]) and session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    result = config.stash.get(_RESULT, None)
    if not result or _is_worker(config):
        return
    comparisons = result.get("comparisons")
    if comparisons is not None:
        from ..report.baseline import format_comparison_table

        terminalreporter.section("pytest-n2r baseline comparison")
        terminalreporter.write_line(
            f"baseline {config.getoption('n2r_compare')}: the same examples replayed and paired; a relation is "
            f"worse when the {result['confidence']:.0%} lower bound of the mean increase of the deviation exceeds "
            f"{result['margin']:g}; failing outcomes: {', '.join(result['fail_on'])}"
        )
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
                + ", ".join(f"{c.nodeid} ({c.outcome})" for c in failed), red=True, bold=True)
    for path in result.get("written", []):
        terminalreporter.write_line(f"pytest-n2r wrote {path}")
