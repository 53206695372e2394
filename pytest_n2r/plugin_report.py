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

_RESULT = pytest.StashKey["dict"]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("n2r")
    group.addoption("--n2r-save-baseline", metavar="PATH", default=None,
                    help="write every relation's examples (scene, view, transform, score) to PATH as JSON")
    group.addoption("--n2r-compare", metavar="PATH", default=None,
                    help="compare each relation's deviations with the baseline at PATH and fail on regressions")
    group.addoption("--n2r-compare-fail", metavar="STAT:LIMIT", action="append", default=None,
                    help="regression rule for --n2r-compare (repeatable, comma-separated): STAT is mean, "
                         "median, p10, p90, max or rate (inconsistency rate); LIMIT an absolute growth of "
                         "the deviation, or a percentage with '%%' (default: mean:0.05)")
    group.addoption("--n2r-report", metavar="PATH", default=None,
                    help="write a self-contained HTML report of every relation to PATH")
    group.addoption("--n2r-json", metavar="PATH", default=None,
                    help="write every relation's results (examples, scores, timings) to PATH as JSON")


def _is_worker(config: pytest.Config) -> bool:
    return hasattr(config, "workerinput")


def pytest_configure(config: pytest.Config) -> None:
    """Check the reporting options up front: a bad rule or a missing baseline is a usage error."""
    if _is_worker(config):
        return
    rules = config.getoption("n2r_compare_fail")
    compare = config.getoption("n2r_compare")
    if rules and not compare:
        raise pytest.UsageError("pytest-n2r: --n2r-compare-fail needs --n2r-compare PATH (the baseline to compare with)")
    if compare:
        from .errors import N2RError
        from .report import load_baseline, parse_compare_rules

        try:
            config.stash[_RESULT] = {
                "rules": parse_compare_rules(rules or ["mean:0.05"]),
                "baseline": load_baseline(compare),
            }
        except N2RError as exc:
            raise pytest.UsageError(f"pytest-n2r: {exc}") from None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Any:
    """Relation results as JUnit XML properties (``n2r_examples``, ``n2r_inconsistencies``, ...).

    An old-style wrapper, like the plugin's, so pytest 7.4 (the declared minimum) works too."""
    outcome = yield
    report = outcome.get_result()
    stats = getattr(report, "n2r_stats", None)
    if call.when == "call" and stats is not None:
        item.user_properties.extend([
            ("n2r_scene", stats["scene"]), ("n2r_metric", stats["metric"]), ("n2r_eps", stats["eps"]),
            ("n2r_examples", stats["examples"]), ("n2r_rejected", sum(stats["rejected"].values())),
            ("n2r_inconsistencies", stats["inconsistencies"]),
            ("n2r_worst_deviation", stats["worst_deviation"]),
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

    from .data.atomic import atomic_write_text
    from .plugin import relation_records
    from .report import compare_runs, save_baseline
    from .report.html import write_html

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
        result["comparisons"] = compare_runs(result["baseline"], records, result["rules"])
        if any(c.failed for c in result["comparisons"]) and session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    result = config.stash.get(_RESULT, None)
    if not result or _is_worker(config):
        return
    comparisons = result.get("comparisons")
    if comparisons is not None:
        from .report.baseline import format_comparison_table

        terminalreporter.section("pytest-n2r baseline comparison")
        terminalreporter.write_line(
            f"baseline {config.getoption('n2r_compare')}, rules: {', '.join(map(str, result['rules']))} "
            "(deviations from each metric's ideal; larger is worse)"
        )
        if comparisons:
            terminalreporter.write_line(format_comparison_table(comparisons))
        else:
            terminalreporter.write_line("no relation ran, nothing compared")
        worse = [c.nodeid for c in comparisons if c.failed]
        if worse:
            terminalreporter.write_line(f"{len(worse)} relation(s) regressed against the baseline: {', '.join(worse)}",
                                        red=True, bold=True)
        missing = sorted(set(result["baseline"]) - {c.nodeid for c in comparisons})
        if missing:
            terminalreporter.write_line(f"in the baseline but not run: {', '.join(missing)}")
    for path in result.get("written", []):
        terminalreporter.write_line(f"pytest-n2r wrote {path}")
