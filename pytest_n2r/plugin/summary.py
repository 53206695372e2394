"""The plugin's terminal summary: every relation's line, the totals, and where the session's time went (at
``-qq``: only the relations that did not pass, and the totals)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import pytest

__all__ = ["Summary"]


class Summary:
    """Collects the relation record of every test report (from xdist workers too) for the summary, and where
    the session's time went: start-up and collection, fixtures' setup, relations, other tests. ``loaded``: when
    pytest loaded the plugin (``time.perf_counter``); ``describe``: the session's settings line."""

    def __init__(self, config: pytest.Config, loaded: float, describe: Callable[[], str]):
        self.config, self.loaded, self.describe = config, loaded, describe
        #: the record of each relation test, by test id, in the order their last reports arrived: a test run again
        #: under the same id (pytest-rerunfailures' ``--reruns``) keeps only its last try's record
        self.recorded: dict[str, Any] = {}
        self.first_report: float | None = None  # when the first test report arrived, less its duration
        self.phases = dict.fromkeys(("setup", "relations", "other tests"), 0.0)
        #: pytest's word for a record whose test was marked xfail (XFAIL, XPASS), or that a pytest outcome raised
        #: inside its run ended (FAILED: pytest-timeout's ``Failed``), by test id
        self.labels: dict[str, str] = {}
        #: the relation tests seen in reports (by their marker: pytest-xdist ships a report's keywords), and
        #: pytest's outcome and reason of the tests that ended without a record
        self.relation_ids: set[str] = set()
        self.unrecorded: dict[str, tuple[str, str]] = {}
        #: how many earlier tries of a test pytest-rerunfailures reported as ``rerun`` (their records dropped)
        self.reruns: dict[str, int] = {}

    @property
    def records(self) -> list[Any]:
        """One record per relation test: the last try's."""
        return list(self.recorded.values())

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if self.first_report is None:
            self.first_report = time.perf_counter() - report.duration
        record = getattr(report, "n2r_record", None)
        if report.when == "call":
            self.phases["relations" if record is not None else "other tests"] += report.duration
        else:
            self.phases["setup"] += report.duration  # setup and teardown: the fixtures' time
        from . import RELATION_MARKER

        if RELATION_MARKER in report.keywords:
            self.relation_ids.add(report.nodeid)
        if report.outcome == "rerun":  # pytest-rerunfailures runs this test again: this try's outcome is not final
            self._superseded(report)
            return
        if record is None or report.when != "call":
            if report.nodeid in self.recorded and report.failed:  # its teardown failed: pytest says ERROR too
                self.recorded[report.nodeid].pytest_outcome = "error"
                self.labels[report.nodeid] = "ERROR"  # and so does the section's line, not the relation's PASSED
            elif report.nodeid not in self.recorded and not report.passed:  # the first word pytest said of it
                self.unrecorded.setdefault(report.nodeid, (_outcome(report), _reason(report)))
            return
        from ..relation.record import RelationRecord

        if report.nodeid in self.recorded:  # run again under its id without a 'rerun' report (--keep-duplicates)
            self.reruns[report.nodeid] = self.reruns.get(report.nodeid, 0) + 1
        self._forget(report.nodeid)  # the last try counts, and the summary says how many were dropped
        added = self.recorded[report.nodeid] = RelationRecord.from_dict(record)
        added.pytest_outcome = _outcome(report)
        if hasattr(report, "wasxfail"):  # xfailed (skipped), or a non-strict xpass (passed)
            self.labels[report.nodeid] = "XFAIL" if report.skipped else "XPASS"
        elif report.failed and str(report.longrepr).startswith("[XPASS(strict)]"):  # pytest's own marking
            self.labels[report.nodeid] = "XPASS"
        elif added.outcome == "error" and added.message and added.message == _reason(report) \
                and added.pytest_outcome in ("failed", "skipped"):
            # pytest's own outcome raised inside the run (pytest-timeout's Failed, a pytest.skip in the SUT) ended
            # it: no error of the relation's, pytest's word
            self.labels[report.nodeid] = added.pytest_outcome.upper()

    def _superseded(self, report: pytest.TestReport) -> None:
        """A try that pytest-rerunfailures reports as ``rerun``: it will run again, so whatever it left is dropped
        and counted (its ``rerun`` attribute numbers the tries from 0; without it, one more)."""
        self._forget(report.nodeid)
        tries = getattr(report, "rerun", None)
        count = tries + 1 if isinstance(tries, int) else self.reruns.get(report.nodeid, 0) + 1
        self.reruns[report.nodeid] = max(count, self.reruns.get(report.nodeid, 0))

    def _forget(self, nodeid: str) -> None:
        """Drop what an earlier try of ``nodeid`` left: its record, its label, pytest's word on it."""
        self.recorded.pop(nodeid, None)
        self.labels.pop(nodeid, None)
        self.unrecorded.pop(nodeid, None)

    def not_run(self) -> list[dict[str, str]]:
        """The relation tests that ended without a relation record, by test id: an error in a fixture's setup,
        the test's body raising or skipping before it returned the SUT, a skip mark, a crashed pytest-xdist worker.
        Each with pytest's outcome (``error``, ``failed``, ``skipped``, ``xfailed``) and its reason."""
        return [{"nodeid": nodeid, "outcome": outcome, "reason": reason}
                for nodeid, (outcome, reason) in sorted(self.unrecorded.items())
                if nodeid in self.relation_ids and nodeid not in self.recorded]

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        """The ``pytest-n2r`` section: each relation's line (with its field-floor lines), the totals line, the
        time line and the settings line. At ``-qq`` (verbosity -2 or less: a CI log of many relations) only the
        lines of the relations that did not plainly pass (failed, xfailed, xpassed, error), with just their
        field-floor warnings (eps below the floor), and the totals line; ``-q`` changes nothing."""
        records = self.records
        if not records:
            return
        terse = self.config.get_verbosity() <= -2
        terminalreporter.section("pytest-n2r")
        from ..relation.floor import annotation_lines
        from ..relation.record import plural

        for record in records:
            reruns = self.reruns.get(record.nodeid, 0)
            if terse and record.pytest_outcome == "passed" and not reruns:  # plainly: no xpass, no rerun, no error
                continue
            tries = "1 earlier try" if reruns == 1 else f"{reruns} earlier tries"
            line = record.summary_line() + (f"; rerun: {tries} under this test id dropped, the last one counts"
                                            if reruns else "")
            label = self.labels.get(record.nodeid)
            terminalreporter.write_line(f"{label:6s} {line.split(' ', 1)[1].lstrip()}" if label else line)
            for line, warn in annotation_lines(record.floor):
                if terse and not warn:
                    continue
                terminalreporter.write_line(f"       {line}", yellow=warn, bold=warn)
        examples = sum(len(r.valid_examples) for r in records)
        calls, shared = sum(r.sut_calls for r in records), sum(r.sut_shared for r in records)
        terminalreporter.write_line(
            f"{plural(len(records), 'relation')}: {plural(examples, 'example')}, "
            f"{sum(r.rejected for r in records)} rejected as invalid, {sum(r.undefined for r in records)} undefined, "
            f"{sum(r.inconsistencies for r in records)} inconsistent; {sum(r.renders for r in records)} renders "
            f"(the rest from the cache); {plural(calls, 'SUT call')} ({shared} outputs reused: the same SUT on the "
            "same render)"
        )
        if terse:
            return
        terminalreporter.write_line(self.time_line())
        terminalreporter.write_line(self.describe())

    def time_line(self) -> str:
        """Where the session's time went: start-up and collection, fixtures, the relations' split, the rest."""
        now = time.perf_counter()
        total = now - self.loaded
        startup = (self.first_report if self.first_report is not None else now) - self.loaded
        from ..relation.record import MORE_TIMINGS, TIMINGS

        parts = (*TIMINGS, *(k for k in MORE_TIMINGS if k != "total"))  # the parts a relation's time splits into
        t = {k: sum(r.timings.get(k, 0.0) for r in self.records) for k in parts}
        other = max(0.0, self.phases["relations"] - sum(t.values()))
        workers = getattr(self.config.option, "numprocesses", None) if hasattr(self.config.option, "dist") else None
        summed = f" (test times summed over the {workers} workers)" if isinstance(workers, int) and workers > 1 else ""
        return (
            f"time {total:.1f} s since pytest loaded pytest-n2r{summed}: start-up and collection {startup:.1f} s; "
            f"fixtures {self.phases['setup']:.1f} s; relations {self.phases['relations']:.1f} s = render "
            f"{t['render']:.2f} s / SUT {t['sut']:.2f} s / metric {t['metric']:.2f} s / validity "
            f"{t['validity']:.2f} s / field floors {t['floor']:.2f} s / search and other {other:.2f} s; other tests "
            f"{self.phases['other tests']:.1f} s"
        )


def _outcome(report: pytest.TestReport) -> str:
    """pytest's final word on a test report: ``passed``, ``failed`` (a strict xfail's pass too: pytest's
    ``[XPASS(strict)]``), ``error`` (in a fixture's setup or teardown), ``skipped``, ``xfailed`` or ``xpassed``."""
    if hasattr(report, "wasxfail"):
        return "xfailed" if report.skipped else "xpassed"
    if report.failed and report.when in ("setup", "teardown"):
        return "error"
    return report.outcome


def _reason(report: pytest.TestReport) -> str:
    """Why a test ended as it did, in one line: a skip's reason, the exception's message, a crash's words."""
    longrepr = report.longrepr
    if isinstance(longrepr, tuple) and len(longrepr) == 3:  # a skip: (path, line, "Skipped: why")
        return str(longrepr[2])
    crash = getattr(longrepr, "reprcrash", None)
    if crash is not None:
        return str(crash.message)
    errorstring = getattr(longrepr, "errorstring", None)
    if errorstring:  # a missing fixture (FixtureLookupErrorRepr)
        return str(errorstring).strip().splitlines()[0]
    lines = [line.strip() for line in str(longrepr or "").splitlines() if line.strip()]
    errors = [line[1:].strip() for line in lines if line.startswith("E ")]  # pytest's marked lines, if any
    return (errors or lines or [""])[0]
