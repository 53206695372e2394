"""The plugin's options, in one registry: flag, ini name, default, parser and help of every ``--n2r-*`` option.

The plugin loops over :data:`OPTIONS` to register them (``pytest_addoption``), to tell whether pytest-n2r is
used at all, and to parse them (:func:`read_options`): the command line wins over the ini file, which wins
over the default; a marker keyword (``@metamorphic(examples=...)``) wins over all three. A value that does
not parse is a ``pytest.UsageError`` naming the flag and the ini key. Defaults that the library objects share
come from :mod:`pytest_n2r.defaults`.

Like the plugin, this module imports only pytest: each parser imports what it needs when it runs.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import pytest

from .. import defaults
from ..errors import InvalidArgument, N2RError
from .path_options import cache_folder, folder, output_file

__all__ = ["Option", "Where", "OPTIONS", "RUN_OPTIONS", "REPORT_OPTIONS", "option", "read_options", "is_used", "on_ci"]


@dataclass(frozen=True)
class Where:
    """Where a value came from: ``origin`` names it in errors (``--n2r-scene``, ``ini n2r_scenes``), relative
    scene paths are taken from ``base`` (the working directory, or the ini file's folder) and relative output
    folders from ``root`` (pytest's rootdir); ``warn`` says what a parser warns of (in a session, as pytest's
    configuration warnings, which its ``-W`` and ``filterwarnings`` reach)."""

    origin: str
    base: Path
    root: Path
    warn: Callable[[str], None] = field(
        default=lambda message: warnings.warn(message, pytest.PytestConfigWarning, stacklevel=3), repr=False,
        compare=False)


@dataclass(frozen=True)
class Option:
    """One ``--n2r-*`` option.

    ``ini`` is its ini twin (``None``: command line only); ``default`` the value used when neither gives
    one, written as a user would type it (``None``: none); ``parse(value, where)`` turns a given value into
    what the session uses and raises :class:`~pytest_n2r.errors.N2RError` with what was expected;
    ``help`` may show the default as ``{default}``. The parser's message is prefixed with the flag and ini
    key, unless ``names_itself`` (its messages already name the option and the entry). ``part`` says which
    half of the plugin reads it: ``"run"`` (the session) or ``"report"`` (baselines and reports). ``typed_bool``:
    a TOML ``true`` / ``false`` reaches ``parse`` as a bool (a folder option's ``false`` is ``none``), not as
    ``yes`` / ``no``.
    """

    flag: str
    ini: str | None
    metavar: str | None
    help: str
    default: str | None = None
    parse: Callable[[Any, Where], Any] | None = None
    action: Literal["store", "append", "store_true"] = "store"
    part: Literal["run", "report"] = "run"
    names_itself: bool = False
    typed_bool: bool = False

    @property
    def dest(self) -> str:
        """The ``config.getoption`` name: the flag without dashes (``--n2r-cache-dir`` → ``n2r_cache_dir``)."""
        return self.flag.lstrip("-").replace("-", "_")

    @property
    def name(self) -> str:
        """The key of :func:`read_options`' result: ``dest`` without ``n2r_`` (``cache_dir``)."""
        return self.dest.removeprefix("n2r_")

    @property
    def help_text(self) -> str:
        return self.help.format(default=self.default)

    def given(self, config: pytest.Config) -> tuple[Any, Where] | None:
        """The value given on the command line, else in the ini file, with where it came from; ``None``
        when neither gives one."""
        root = Path(config.rootpath)
        value = config.getoption(self.dest)
        if value not in (None, False):
            return value, Where(self.flag, Path.cwd(), root)
        if self.ini is not None:
            try:
                value = config.getini(self.ini)
            except TypeError:  # pytest 9's TOML table ([pytest], [tool.pytest]) holds a number, a bool, ...
                value = self._typed_ini(config)
            else:  # [tool.pytest.ini_options] hands a TOML bool over as "True" / "False"
                if self.typed_bool and value in ("True", "False") and f"{config.inipath}".endswith(".toml"):
                    typed = self._typed_ini(config)
                    value = typed if isinstance(typed, bool) else value
            if isinstance(value, list) and self.action != "append":
                raise self._usage_error(f"{value!r} is a list; expected one value, not a list")
            if value not in (None, "", []):
                base = Path(config.inipath).parent if config.inipath else root
                return value, Where(f"ini {self.ini}", base, root)
        return None

    def _typed_ini(self, config: pytest.Config) -> str | bool | list[str] | None:
        """The ini value as a TOML configuration file types it (``n2r_examples = 7``, ``n2r_derandomize = true``),
        which pytest 9 refuses for an option registered as text, written as text for :attr:`parse` (a bool as
        ``yes`` / ``no``, or kept a bool where :attr:`typed_bool`; a list option's string split at whitespace, as
        in an ini file)."""
        if sys.version_info >= (3, 11):
            import tomllib
        else:  # Python 3.10: pytest's own TOML reader (mypy run on 3.11 or later has no tomli to read)
            import tomli as tomllib  # type: ignore[import-not-found, unused-ignore]

        assert config.inipath is not None  # the value came from a TOML configuration file
        path = Path(config.inipath)
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        table = data.get("tool", {}).get("pytest", {}) if path.name == "pyproject.toml" else data.get("pytest", {})
        value = table.get("ini_options", table).get(self.ini)
        if isinstance(value, list):
            return [_ini_text(v) for v in value]
        if self.action == "append" and isinstance(value, str):
            return value.split()
        if isinstance(value, bool) and self.typed_bool:
            return value
        return None if value is None else _ini_text(value)

    def _usage_error(self, message: str) -> pytest.UsageError:
        """``message`` as a usage error, prefixed with the flag and the ini key unless :attr:`names_itself`."""
        where = "" if self.names_itself else f"{self.flag}{f' / ini {self.ini}' if self.ini else ''}: "
        return pytest.UsageError(f"pytest-n2r: {where}{message}")

    def value(self, config: pytest.Config) -> Any:
        """The parsed value: given (command line, ini file) or the default; a bad one is a usage error."""
        given = self.given(config)
        if given is None:
            if self.default is None:
                return None if self.action != "store_true" else False
            given = self.default, Where("default", Path(config.rootpath), Path(config.rootpath))
        if self.parse is None:
            return given[0]
        where = replace(given[1], warn=lambda message: config.issue_config_time_warning(
            pytest.PytestConfigWarning(message), stacklevel=2))
        try:
            return self.parse(given[0], where)
        except N2RError as exc:
            raise self._usage_error(f"{exc}") from None


def _ini_text(value: Any) -> str:
    """A TOML value as an ini file writes it: ``true`` as ``yes``, ``7`` as ``7``, a string as itself."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    return value if isinstance(value, str) else f"{value}"


# -- parsers (each imports what it needs when it runs) -----------------------------------------------------


def _whole_number(value: str, where: Where) -> int:
    try:
        number = int(value)
    except ValueError:
        number = 0
    if number < 1:
        raise InvalidArgument(f"{value!r} is not a whole number >= 1")
    return number


def _number_in(low: float, high: float, what: str) -> Callable[[str, Where], float]:
    def parse(value: str, where: Where) -> float:
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not low <= number <= high:
            raise InvalidArgument(f"{value!r} is not {what}")
        return number

    return parse


def _render_size(value: str, where: Where) -> Any:
    from ..render.size import RenderSize

    return RenderSize.parse(str(value), "n2r_size")


def _device(value: str, where: Where) -> str:
    from ..field.device import check_device

    return check_device(str(value).strip().lower())  # a CUDA device checked now, not at every test's setup


def _byte_size(value: str, where: Where) -> int:
    from .._validation import parse_size

    return parse_size(str(value), "n2r_cache_size")


def _switch(text: str, expected: str) -> bool:
    """``yes`` / ``no`` (or ``true`` / ``false``, ``1`` / ``0``) as a bool; else an error saying ``expected``."""
    if text not in ("yes", "no", "true", "false", "1", "0"):
        raise InvalidArgument(f"{text!r}; expected {expected}")
    return text in ("yes", "true", "1")


def _derandomize(value: str, where: Where) -> bool:
    text = str(value).strip().lower()
    return on_ci() if text == "auto" else _switch(text, "auto, yes or no")


def on_ci() -> bool:
    """Whether the ``CI`` environment variable says this runs on CI: set to anything but empty, ``0``, ``false``
    or ``no`` (any case; ``CI=false`` turns a CI-like environment's default off)."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def _yes_no(value: str, where: Where) -> bool:
    return _switch(str(value).strip().lower(), "yes or no")


def _scenes(entries: list[str], where: Where) -> list[Any]:
    """Scene specs; each scene file is opened and checked now, so a broken one is a usage error."""
    from .scenes import parse_scene_specs

    specs = parse_scene_specs(entries, where.base, where.origin)
    for spec in specs:
        if spec.kind == "file":
            from ..scene.file import check_scene_file  # here: a run without scene files never loads the field

            try:
                check_scene_file(spec.source)
            except N2RError as exc:
                raise InvalidArgument(f"--n2r-scene / ini n2r_scenes {spec.source}: {exc}") from None
    return specs


def _probability(value: str, where: Where) -> float:
    from ..report.compare import check_confidence

    try:
        return check_confidence(float(value))
    except (ValueError, InvalidArgument):
        raise InvalidArgument(f"--n2r-compare-confidence={value!r} is not a probability in (0.5, 1), e.g. 0.95"
                              ) from None


def _margin(spec: str | list[str], where: Where) -> float:
    from ..report import parse_margin

    return parse_margin(spec)


def _outcomes(spec: str | list[str], where: Where) -> tuple[str, ...]:
    from ..report import parse_outcomes

    return parse_outcomes(spec)


def _baseline(path: str, where: Where) -> Any:
    from ..report import load_baseline

    return load_baseline(path)


def _text(number: float) -> str:
    return f"{number:g}"


#: The longest ``--n2r-timeout``, a day: no render or SUT call needs more, and far longer ones overflow the
#: platform's timer (``inf``, 1e12); 0 is the way to say "no limit".
MAX_TIMEOUT_S = 86400.0

#: Every option, in the order ``pytest --help`` lists them.
OPTIONS: tuple[Option, ...] = (
    Option("--n2r-scene", "n2r_scenes", "PATH",
           "scene to test on: a .n2r file, 'demo:<name>' or 'module:function' (repeatable; ini: globs allowed, "
           "whitespace-separated). Default: the first built-in demo scene",
           parse=_scenes, action="append", names_itself=True),
    Option("--n2r-examples", "n2r_examples", "N", "Hypothesis examples per relation (default: {default})",
           default=str(defaults.EXAMPLES), parse=_whole_number),
    Option("--n2r-size", "n2r_size", "WxH",
           "render size: 'WxH' (a box the view fits in, its aspect kept) or the longer side in pixels "
           "(default: {default})",
           default="480", parse=_render_size),
    Option("--n2r-render-scale", "n2r_render_scale", "S",
           "render scene fields at this fraction of the render size and upsample to it: 0.5 is about 4x faster "
           "for a little sharpness (default: {default})",
           default=_text(defaults.RENDER_SCALE), parse=_number_in(0.1, 1.0, "a fraction in [0.1, 1]")),
    Option("--n2r-device", "n2r_device", "DEVICE",
           "device for scene fields: auto, cpu, cuda, cuda:1 (default: {default})",
           default=defaults.DEVICE, parse=_device),
    Option("--n2r-cache-dir", "n2r_cache_dir", "DIR",
           "render cache directory, relative to the rootdir; 'none' keeps renders in memory only "
           "(default: {default})", default=".n2r-cache", parse=cache_folder,
           typed_bool=True),
    Option("--n2r-cache-size", "n2r_cache_size", "SIZE", "disk cap of the render cache, e.g. 2GiB (default: {default})",
           default=defaults.CACHE_SIZE, parse=_byte_size),
    Option("--n2r-artifacts", "n2r_artifacts", "DIR",
           "where failure pictures go, relative to the rootdir; 'none' saves none (default: {default})",
           default="n2r-artifacts", parse=folder, typed_bool=True),
    Option("--n2r-timeout", "n2r_timeout", "SECONDS",
           f"time limit of one render or one SUT call, at most {MAX_TIMEOUT_S:g} (a day); 0 disables "
           "(default: {default})", default=_text(defaults.TIMEOUT_S),
           parse=_number_in(0.0, MAX_TIMEOUT_S, f"a number of seconds >= 0 and <= {MAX_TIMEOUT_S:g} (0: no limit)")),
    Option("--n2r-derandomize", "n2r_derandomize", "auto|yes|no",
           "draw the same examples every run; 'auto' means yes when the CI environment variable is set (not "
           "to '', 0, false or no) (default: {default})", default="auto", parse=_derandomize),
    Option("--n2r-precompile", "n2r_precompile", "yes|no",
           "on the first render, compile the kernels of the other renderers the tests use in a helper process, "
           "on an idle core, and kernel pieces while a first render waits for another process's kernels "
           "(default: {default})", default="yes", parse=_yes_no),
    Option("--n2r-cache-clear", None, None, "empty the render cache before the run", action="store_true"),
    Option("--n2r-save-baseline", None, "PATH",
           "write every relation's drawn examples (all a replay needs, and their deviations) to PATH",
           parse=output_file, part="report"),
    Option("--n2r-compare", None, "PATH",
           "replay the baseline's examples at PATH, pair them with this run's and fail on regressions",
           parse=_baseline, part="report", names_itself=True),
    Option("--n2r-compare-fail", None, "mean:MARGIN",
           "regression rule for --n2r-compare: fail a relation when the lower confidence bound of the mean "
           "increase of the deviation over its paired examples exceeds MARGIN (default: {default})",
           default=f"mean:{defaults.COMPARE_MARGIN:g}", parse=_margin, action="append", part="report",
           names_itself=True),
    Option("--n2r-compare-confidence", None, "P",
           "confidence of that one-sided bound, in (0.5, 1) (default: {default})",
           default=_text(defaults.COMPARE_CONFIDENCE), parse=_probability, part="report", names_itself=True),
    Option("--n2r-compare-fail-on", None, "OUTCOMES",
           "comma-separated comparison outcomes that fail the run (default: {default}; also possible: new, "
           "changed-eps)", default=", ".join(defaults.COMPARE_FAIL_ON), parse=_outcomes, action="append",
           part="report", names_itself=True),
    Option("--n2r-report", None, "PATH", "write a self-contained HTML report of every relation to PATH",
           parse=output_file, part="report"),
    Option("--n2r-json", None, "PATH",
           "write every relation's results (examples, scores, timings) to PATH as JSON (NaN where a value is "
           "undefined)", parse=output_file, part="report"),
)
RUN_OPTIONS = tuple(o for o in OPTIONS if o.part == "run")
REPORT_OPTIONS = tuple(o for o in OPTIONS if o.part == "report")


def option(name: str) -> Option:
    """The option called ``name`` (``"examples"``, ``"compare_fail"``)."""
    return next(o for o in OPTIONS if o.name == name)


def add_options(parser: pytest.Parser) -> None:
    """Register every option in the ``n2r`` group, and the ini twin of those that have one."""
    group = parser.getgroup("n2r", "pytest-n2r: metamorphic tests on rendered views")
    for o in OPTIONS:
        kwargs: dict[str, Any] = {"dest": o.dest, "help": o.help_text}
        if o.action == "store_true":
            group.addoption(o.flag, action="store_true", default=False, **kwargs)
        else:
            group.addoption(o.flag, action=o.action, metavar=o.metavar, default=None, **kwargs)
        if o.ini is not None:
            if o.action == "append":
                parser.addini(o.ini, o.help_text, type="args", default=[])
            else:
                parser.addini(o.ini, o.help_text, default=None)


def is_used(config: pytest.Config, options: tuple[Option, ...] = RUN_OPTIONS) -> bool:
    """Whether any of ``options`` is given, on the command line or in the ini file."""
    return any(o.given(config) is not None for o in options)


def read_options(config: pytest.Config, options: tuple[Option, ...] = RUN_OPTIONS) -> dict[str, Any]:
    """Every option of ``options`` parsed, by :attr:`Option.name` (a bad value is a usage error)."""
    return {o.name: o.value(config) for o in options}
