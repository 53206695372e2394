"""Baselines: save every example of a run, replay exactly those examples later and compare them in pairs.

A baseline is JSON with stable ordering (sorted keys, relations by test id) so it diffs well in review. It
holds, per relation, one record per drawn example with all a replay needs (see
:class:`~pytest_n2r.relation.record.ExampleRecord`). ``--n2r-compare`` replays the baseline's accepted
examples on the current code, pairs each with its baseline record and judges the per-example changes of
the **deviation** (0 = ideal, larger = worse, whatever the metric's direction): the relation regressed when
a one-sided Student t lower confidence bound of the mean increase exceeds the margin the user sets
(:func:`compare_paired`). Unchanged code gives identical deviations (renders and SUTs are deterministic),
so its bound is exactly 0.

Every number of a baseline is checked on load (:func:`load_baseline`): a baseline that could silently pass
a regression (no relations, a NaN deviation, a malformed example) is a :class:`BaselineError` naming the
file, the relation, the example and the field.
"""

from __future__ import annotations

import json
import math
import os
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ..data.atomic import atomic_write_text
from ..data.relative_path import relative_posix
from ..errors import BaselineError
from ..relation.record import RelationRecord
from .validate import BadField, DuplicateKey, check_version, meta_from_json, relation_from_json, unique_keys

__all__ = ["FORMAT", "VERSION", "BaselineError", "Baseline", "save_baseline", "load_baseline", "describe_baseline",
           "portable_places", "setting_differences"]

FORMAT = "pytest-n2r-baseline"
VERSION = 2


class Baseline(dict):
    """A loaded baseline: its relation records by test id, and :attr:`not_recorded`, the relation test ids the
    session that saved it collected but recorded nothing for (deselected with ``-k`` / ``-m`` / ``--deselect``,
    skipped, or not run): a comparison reports those as ``missing``, not ``new``."""

    not_recorded: frozenset[str] = frozenset()

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        #: Where the baseline came from (:data:`~pytest_n2r.report.validate.META_FIELDS`), as far as the file
        #: records it (older files: nothing).
        self.meta: dict[str, Any] = {}


# -- writing --------------------------------------------------------------------------------------------


def _plain_number(value: float) -> float | None:
    """JSON has no NaN: a non-finite number (the score of a rejected or undefined example) is written null."""
    return value if isinstance(value, (int, float)) and math.isfinite(value) else None


def save_baseline(path: str | os.PathLike, relations: list[RelationRecord], meta: dict | None = None) -> Path:
    """Write every relation's drawn examples (all statuses, replay data included) to ``path`` atomically:
    strict JSON, relations sorted by test id, one line per example (so a review diff shows which changed).
    ``meta`` (:data:`~pytest_n2r.report.validate.META_FIELDS`) gets the pytest-n2r version and the time of saving
    unless it gives them."""
    def line(value: Any) -> str:
        return json.dumps(value, sort_keys=True, allow_nan=False)

    from .. import __version__

    saved = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    meta = {"pytest_n2r": __version__, "saved": saved, **(meta or {})}

    parts = []
    for r in sorted(relations, key=lambda r: r.nodeid):
        head = {"metric": r.metric, "eps": r.eps, "scene": r.scene, "scene_hash": r.scene_hash, "outcome": r.outcome}
        examples = ",\n".join(
            "    " + line({**{k: v for k, v in e.to_dict().items() if k != "images"},
                          "score": _plain_number(e.score), "deviation": _plain_number(e.deviation)})
            for e in r.examples)
        fields = ",\n".join(f"   {json.dumps(k)}: {line(v)}" for k, v in sorted(head.items()))
        parts.append(f"  {json.dumps(r.nodeid)}: {{\n{fields},\n   \"examples\": [\n{examples}\n   ]\n  }}")
    text = (f'{{\n "format": "{FORMAT}",\n "meta": {line(meta or {})},\n "relations": {{\n' + ",\n".join(parts)
            + f"\n }},\n \"version\": {VERSION}\n}}\n")
    json.loads(text)  # what is written must read back
    return atomic_write_text(path, text)


# -- reading and validating -----------------------------------------------------------------------------


def load_baseline(path: str | os.PathLike) -> Baseline:
    """Read and validate a baseline written by :func:`save_baseline`; :class:`BaselineError` names what
    is wrong (file, relation, example, field) and how to fix it."""
    path = Path(path).expanduser()  # `--n2r-compare=~/b.json`: no shell expands a ~ after '='
    regenerate = f"regenerate it with --n2r-save-baseline {path}"
    if path.is_dir():
        raise BaselineError(f"baseline {path} is a folder; expected a baseline file (the JSON file that "
                            f"--n2r-save-baseline PATH writes, e.g. {path / 'n2r-baseline.json'})")
    if not path.is_file():
        raise BaselineError(f"baseline {path} does not exist; create it with --n2r-save-baseline {path}")
    text = ""
    try:
        text = path.read_text(encoding="utf-8")
        data = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=unique_keys)
    except DuplicateKey as exc:
        raise BaselineError(f"baseline {path}: {exc.where(text)}, or {regenerate}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, ValueError) as exc:
        raise BaselineError(f"baseline {path} is not readable JSON: {exc}; {regenerate}") from None
    except RecursionError:
        raise BaselineError(f"baseline {path} is not readable JSON: nested too deeply for the JSON parser; "
                            f"{regenerate}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise BaselineError(f"baseline {path} is not a pytest-n2r baseline (missing \"format\": \"{FORMAT}\")")
    wrong_version = check_version(data, VERSION)
    if wrong_version is not None:
        newer = isinstance(data.get("version"), int) and data["version"] > VERSION
        raise BaselineError(f"baseline {path} {wrong_version}" + ("" if newer else f"; {regenerate}"))
    relations = data.get("relations")
    if not isinstance(relations, dict) or not relations:
        raise BaselineError(
            f"baseline {path} has no relations: it would let every relation pass as new; {regenerate} "
            "on a run that has relation tests"
        )
    out = Baseline()
    for nodeid, rel in relations.items():
        try:
            out[nodeid] = relation_from_json(nodeid, rel)
        except BadField as exc:
            raise BaselineError(f"baseline {path}: relation {nodeid!r}: {exc}; {regenerate}") from None
    try:
        meta = meta_from_json(data.get("meta"))
    except BadField as exc:
        raise BaselineError(f"baseline {path}: {exc}; {regenerate}") from None
    out.not_recorded = frozenset(meta.get("not_recorded", ())) - set(out)
    out.meta = {k: v for k, v in meta.items() if k != "not_recorded"}
    return out


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number JSON allows (pytest-n2r writes null for 'no value')")


# -- where a baseline came from ------------------------------------------------------------------------


def _setting(key: str, value: Any) -> str:
    if key == "derandomize":
        return "yes" if value else "no"
    if key == "scenes":
        return ", ".join(value) or "none"
    return "none" if value is None else f"{value}"


#: The settings a baseline records, as the comparison's header names them. ``examples`` is the session's
#: ``--n2r-examples`` default: a relation's own ``examples=`` overrides it, and the baseline's examples are its own.
_SETTINGS = {"size": "render size", "examples": "--n2r-examples default", "derandomize": "derandomize",
             "scenes": "scenes"}


#: Where a baseline was saved from, as it records it: pytest's rootdir from the baseline's folder and the config file
#: from the rootdir (:func:`portable_places`). A path that is absolute (an older baseline's) is not compared.
_PLACES = {"rootdir": "rootdir (from the baseline's folder)", "config_file": "config file (from the rootdir)"}


def portable_places(settings: dict[str, Any], baseline: str | os.PathLike) -> dict[str, Any]:
    """``settings`` with its absolute ``rootdir`` made relative to the folder of the ``baseline`` file and its
    ``config_file`` relative to the rootdir, ``/``-separated: a baseline committed to a repository names nobody's
    home folder, reads the same on every clone and CI machine, and a run from another rootdir is told apart (its
    test ids differ). A path on another drive (Windows) stays absolute.

    >>> portable_places({"rootdir": "/src/proj", "config_file": "/src/proj/pyproject.toml", "size": "480"},
    ...                 "/src/proj/tests/gate.json")
    {'rootdir': '..', 'config_file': 'pyproject.toml', 'size': '480'}
    """
    out = dict(settings)
    if settings.get("rootdir"):  # resolved: pytest keeps a rootdir reached through a link as given
        out["rootdir"] = relative_posix(settings["rootdir"], Path(baseline).expanduser().resolve().parent)
        if settings.get("config_file"):
            out["config_file"] = relative_posix(settings["config_file"], settings["rootdir"])
    return out


def describe_baseline(meta: dict[str, Any]) -> str:
    """One line saying which baseline this is: its pytest-n2r version, date, pytest rootdir and config file,
    and the settings it was saved with, as far as its ``meta`` records them.

    >>> describe_baseline({"pytest_n2r": "0.1.0", "saved": "2024-12-07T03:20:11Z", "size": "480", "examples": 20,
    ...                    "derandomize": True, "scenes": ["wall"]})
    'baseline saved 2024-12-07T03:20:11Z by pytest-n2r 0.1.0; render size 480, --n2r-examples default 20, derandomize yes, scenes wall'
    >>> describe_baseline({})
    'baseline saved by an older pytest-n2r, which did not record its version, date or settings'
    """  # noqa: E501
    if not any(k in meta for k in ("pytest_n2r", "saved", *_SETTINGS)):
        return "baseline saved by an older pytest-n2r, which did not record its version, date or settings"
    by = f" by pytest-n2r {meta['pytest_n2r']}" if "pytest_n2r" in meta else ""
    where = [f"{_PLACES[k] if _relative(meta[k]) else k.replace('_', ' ')} {meta[k] or 'none'}"
             for k in _PLACES if k in meta]
    settings = [f"{name} {_setting(k, meta[k])}" for k, name in _SETTINGS.items() if k in meta]
    return (f"baseline saved {meta.get('saved', '(date not recorded)')}{by}"
            + (f" ({', '.join(where)})" if where else "") + (f"; {', '.join(settings)}" if settings else ""))


def setting_differences(meta: dict[str, Any], current: dict[str, Any]) -> list[str]:
    """The settings (render size, --n2r-examples default, derandomize, scenes; the rootdir and config file where the
    baseline records them relative, see :func:`portable_places`, as ``current`` must too) of this run that differ
    from those the baseline recorded, each as ``"render size 64 (baseline: 480)"``; none where the baseline did not
    record them.

    >>> setting_differences({"size": "480", "scenes": ["wall"]}, {"size": "64", "scenes": ["wall"]})
    ['render size 64 (baseline: 480)']
    >>> setting_differences({"rootdir": ".."}, {"rootdir": "../.."})
    ["rootdir (from the baseline's folder) ../.. (baseline: ..)"]
    """
    def same(key: str) -> bool:
        a, b = meta[key], current[key]
        return sorted(a) == sorted(b) if key == "scenes" else a == b

    names = {**_SETTINGS, **{k: name for k, name in _PLACES.items() if k in meta and _relative(meta[k])}}
    return [f"{name} {_setting(k, current[k])} (baseline: {_setting(k, meta[k])})" for k, name in names.items()
            if k in meta and k in current and not same(k)]


def _relative(path: str | None) -> bool:
    """Whether a recorded place is relative (a baseline's since :func:`portable_places`), not an older absolute one."""
    return path is not None and not Path(path).is_absolute() and not path.startswith(("/", "\\"))
