"""Validating what a baseline file holds, field by field, before anything reads it (:func:`relation_from_json`,
:func:`meta_from_json`).

A field that fails is a :class:`BadField` naming it (``examples[3].camera.distortion=5; expected ...``);
:func:`~pytest_n2r.report.baseline.load_baseline` adds the file and the relation and turns it into a
:class:`~pytest_n2r.report.baseline.BaselineError`. Whatever passes builds an
:class:`~pytest_n2r.relation.record.ExampleRecord` without a ``TypeError`` and replays (every follow-up
rebuildable), and whatever pairs with a replay does so exactly: a transform is filled to its six fields and a
mutation to all of its parameters, as the engine records them.
"""

from __future__ import annotations

import json
import math
from typing import Any

from .._validation import is_finite
from ..errors import InvalidArgument, InvalidType, N2RError
from ..geometry import Camera, Transform
from ..relation.record import STATUSES, ExampleRecord, RelationRecord

__all__ = ["META_FIELDS", "BadField", "DuplicateKey", "unique_keys", "check_version",
           "relation_from_json", "meta_from_json"]

_CAMERA_INTS = ("width", "height")
_CAMERA_FLOATS = ("fx", "fy", "cx", "cy")
#: What each field of a camera record holds, for messages; the rules on the values are
#: :class:`~pytest_n2r.geometry.Camera`'s own.
_CAMERA_FIELDS = {"width": "a whole number of pixels", "height": "a whole number of pixels",
                  "fx": "a focal length in pixels", "fy": "a focal length in pixels",
                  "cx": "a principal point coordinate in pixels", "cy": "a principal point coordinate in pixels",
                  "distortion": "OpenCV's distortion coefficients k1 k2 p1 p2 [k3 [k4 k5 k6]]"}


class BadField(Exception):
    """A field of a baseline that fails validation (the message names it)."""


class DuplicateKey(ValueError):
    """A JSON object that gives one key twice (a JSON reader keeps the last and silently drops the other); its
    message names the key, and :meth:`where` the object it sits in."""

    def __init__(self, key: str) -> None:
        self.key = key
        super().__init__(self._message("one object"))

    def _message(self, where: str) -> str:
        return (f"the key {self.key!r} appears twice in {where} (a JSON reader keeps only the last and drops the "
                "other without a word: a hand edit or a merge?); keep one of them")

    def where(self, text: str) -> str:
        """The message, naming the object of the JSON ``text`` that gives the key twice (``in relations``, ``in
        relations['a.py::test_a[wall]'].examples[3]``) where the text can be read again; as before where not."""
        place = _where_duplicate(text)
        return self._message(place) if place else str(self)


def unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """``json.loads``' ``object_pairs_hook``: the object as a dict, or :class:`DuplicateKey` naming the key."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise DuplicateKey(key)
        out[key] = value
    return out


def _where_duplicate(text: str) -> str:
    """Where the object sits that :func:`unique_keys` refuses first (the first one JSON completes with a key twice):
    ``the top-level object``, ``relations``, ``relations['a::t'].examples[3]``; ``""`` where it cannot tell."""
    twice: list[dict] = []

    def keep(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        out = dict(pairs)
        if len(out) < len(pairs) and not twice:
            twice.append(out)
        return out

    def path(node: Any, where: str) -> str | None:
        if node is twice[0]:
            return where
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
        for key, value in items:
            inner = (f"{where}[{key}]" if isinstance(key, int) else key if not where
                     else f"{where}.{key}" if key.isidentifier() else f"{where}[{key!r}]")
            found = path(value, inner)
            if found is not None:
                return found
        return None

    try:
        data = json.loads(text, object_pairs_hook=keep)
        return (path(data, "") or "the top-level object") if twice else ""
    except (ValueError, RecursionError):
        return ""


def check_version(data: dict, version: int) -> str | None:
    """Why the baseline's ``"version"`` is not ``version`` (``None`` when it is), and what to do: an older one is
    saved again, a newer one needs a newer pytest-n2r (saving it again with this one, on the branch under review,
    would compare the candidate with itself), and a version that is not an integer is malformed."""
    found = data.get("version")
    if found == version and type(found) is int:
        return None
    if "version" not in data:
        return f"has no \"version\"; expected the integer {version} (the format version this pytest-n2r reads)"
    if type(found) is not int:
        return (f"has \"version\": {found!r} ({type(found).__name__}); expected an integer, the format version "
                f"(this pytest-n2r reads {version})")
    if found > version:
        return (f"has format version {found}; this pytest-n2r reads version {version}: it was written by a newer "
                "pytest-n2r; upgrade pytest-n2r to read it (do not save it again with this one: on a pull request "
                "that would compare the candidate with itself)")
    return f"has format version {found}; this pytest-n2r reads version {version} (paired replay)"


def _number(value: Any, where: str, *, minimum: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not is_finite(value):
        raise BadField(f"{where}={value!r}; expected a finite number")
    if minimum is not None and value < minimum:
        raise BadField(f"{where}={value!r}; expected a number >= {minimum:g}")
    return float(value)


def _text(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise BadField(f"{where}={value!r}; expected a string")
    return value


def _present(e: dict, key: str, where: str, expected: str) -> Any:
    if key not in e:
        raise BadField(f"{where} is missing the field {key!r} ({expected})")
    return e[key]


#: The fields of a baseline's relation entry and of its example records (what :func:`save_baseline` writes; an
#: example's ``images`` and ``valid`` are :class:`ExampleRecord` data too): any other is refused, naming it.
_RELATION_FIELDS = ("metric", "eps", "scene", "scene_hash", "outcome", "examples")
_EXAMPLE_FIELDS = tuple(sorted({*ExampleRecord.__dataclass_fields__, "valid"}))


def _known_fields(record: dict, known: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(record) - set(known))
    if unknown:
        raise BadField(f"{where}: " * bool(where) + f"unknown field(s) {unknown} (misspelt?); expected fields of "
                       f"{list(known)}")


def relation_from_json(nodeid: str, rel: Any) -> RelationRecord:
    """The relation record of one entry of a baseline's ``relations``, every field checked."""
    if not isinstance(rel, dict):
        raise BadField(f"expected an object, got {type(rel).__name__}")
    _known_fields(rel, _RELATION_FIELDS, "")
    for key in ("metric", "eps", "scene_hash", "examples"):
        if key not in rel:
            raise BadField(f"missing field {key!r}")
    examples = rel["examples"]
    if not isinstance(examples, list):
        raise BadField(f"examples={type(examples).__name__}; expected a list of example records")
    return RelationRecord(
        nodeid=nodeid, metric=_text(rel["metric"], "metric"), eps=_number(rel["eps"], "eps", minimum=0),
        scene=_text(rel.get("scene", ""), "scene"), scene_hash=_text(rel["scene_hash"], "scene_hash"),
        outcome=_text(rel.get("outcome", "passed"), "outcome"),
        examples=[_example(e, f"examples[{i}]") for i, e in enumerate(examples)],
    )


def meta_from_json(meta: Any) -> dict[str, Any]:
    """A baseline's ``meta`` object, checked: ``not_recorded`` (relation test ids the saving session collected but
    recorded nothing for: deselected, skipped or not run) must be a list of strings, and where it came from
    (version, date, rootdir, settings: :data:`META_FIELDS`) of the right types where given; a field it does not
    know is kept (a newer pytest-n2r's)."""
    if meta is None:
        return {}
    if not isinstance(meta, dict):
        raise BadField(f"meta={meta!r}; expected an object")
    for key, (kinds, _, expected) in META_FIELDS.items():  # all optional: older files lack them
        value = meta.get(key)
        if key in meta and (not isinstance(value, kinds) or isinstance(value, bool) and bool not in kinds
                            or list in kinds and not all(isinstance(n, str) for n in value)):
            raise BadField(f"meta.{key}={value!r}; expected {expected}")
    return meta


#: What a baseline's ``meta`` records about the session that saved it, each field's types and what it is (for the
#: docs and the messages). All are optional (older files lack them); a field not here is kept (a newer pytest-n2r's).
META_FIELDS: dict[str, tuple[tuple[type[Any], ...], str, str]] = {
    "not_recorded": ((list,), "relation test ids collected but not run (deselected or skipped)", "a list of test ids"),
    "pytest_n2r": ((str,), "the pytest-n2r version that saved it", "the pytest-n2r version, a string"),
    "saved": ((str,), "when, in UTC (ISO 8601, to the second)", "a UTC date, a string"),
    "rootdir": ((str,), "pytest's rootdir, from the baseline's folder ('..'; absolute in older files)",
                "a path, a string"),
    "config_file": ((str, type(None)), ("pytest's config file, from the rootdir ('pyproject.toml'; absolute in "
                                        "older files; null: none)"), "a path, a string, or null"),
    "size": ((str,), "the render size (--n2r-size)", "a render size, a string such as '480' or '320x180'"),
    "examples": ((int,), "the --n2r-examples default (a relation's own examples= overrides it)", "a whole number"),
    "derandomize": ((bool,), "whether the examples were derandomized", "true or false"),
    "scenes": ((list,), "the configured scenes' names, as test ids carry them (--n2r-scene)", "a list of scene names"),
}


def _camera(camera: Any, where: str) -> None:
    """Checks the types of the camera record's fields here, then its values by building the
    :class:`~pytest_n2r.geometry.Camera` (what a replay builds), naming the field that fails."""
    if not isinstance(camera, dict):
        raise BadField(f"{where} must be an object with width, height, fx, fy, cx, cy")
    for key in _CAMERA_INTS:
        value = camera.get(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise BadField(f"{where}.{key}={value!r}; expected {_CAMERA_FIELDS[key]}")
    for key in _CAMERA_FLOATS:
        _number(camera.get(key), f"{where}.{key}")
    distortion = camera.get("distortion", [])
    if not isinstance(distortion, list):
        raise BadField(f"{where}.distortion={distortion!r}; expected a list of 0, 4, 5 or 8 numbers (OpenCV's "
                       "k1 k2 p1 p2 [k3 [k4 k5 k6]])")
    for k, value in enumerate(distortion):
        _number(value, f"{where}.distortion[{k}]")
    try:
        Camera.from_dict(camera)
    except (InvalidArgument, InvalidType) as exc:
        # Camera's messages start with the field they name ("Camera fx=0.0 must be > 0")
        named = next((k for k in _CAMERA_FIELDS if str(exc).startswith(f"Camera {k}")), None)
        if named is None:
            raise BadField(f"{where}: {exc}") from None
        raise BadField(f"{where}.{named}={camera.get(named)!r}; expected {_CAMERA_FIELDS[named]} ({exc})") from None


def _follow_up(e: dict, where: str) -> tuple[dict[str, float] | None, dict[str, Any] | None]:
    """The example's transform, filled to its six fields, or its mutation with all of its parameters."""
    transform = _present(e, "transform", where, "an object with fields of the pose transform, or null for a mutation")
    mutation = e.get("mutation")
    if mutation is not None:
        if not isinstance(mutation, dict) or not isinstance(mutation.get("name"), str):
            raise BadField(f"{where}.mutation={mutation!r}; expected an object with the mutation's 'name' and its "
                           "parameters")
        from ..strategies.mutation import is_registered, mutation_from_dict

        # A mutation class of a test module is defined only once the tests are collected, after the baseline is
        # read: such a record is kept as written, and rebuilt (or refused, naming it) when the example replays.
        if is_registered(mutation["name"]):
            try:
                mutation = mutation_from_dict(mutation).as_dict()  # all of its parameters, as the engine records them
            except (N2RError, TypeError, ValueError) as exc:
                raise BadField(f"{where}.mutation: {exc}") from None
    if transform is not None:
        if not isinstance(transform, dict) or set(transform) - set(Transform.COMPONENTS):
            raise BadField(f"{where}.transform={transform!r}; expected an object with fields of {Transform.COMPONENTS}")
        # filled to the six fields the engine records, so that the example pairs with its replay
        transform = {key: _number(transform.get(key, 0.0), f"{where}.transform.{key}") for key in Transform.COMPONENTS}
    if transform is None and mutation is None:
        raise BadField(f"{where} has neither a transform nor a mutation")
    if transform is not None and mutation is not None:
        raise BadField(f"{where} has both a transform and a mutation; expected one follow-up (the other null)")
    return transform, mutation


def _example(e: Any, where: str) -> ExampleRecord:
    if not isinstance(e, dict):
        raise BadField(f"{where} is {type(e).__name__}; expected an example object")
    _known_fields(e, _EXAMPLE_FIELDS, where)
    status = e.get("status")
    if status not in STATUSES:
        raise BadField(f"{where}.status={status!r}; expected one of {STATUSES}")
    _text(_present(e, "scene", where, "the scene's name"), f"{where}.scene")
    _text(e.get("view"), f"{where}.view")
    _text(e.get("scene_hash", ""), f"{where}.scene_hash")
    _text(e.get("reason", ""), f"{where}.reason")
    settings = e.get("settings", {})
    if not isinstance(settings, dict):
        raise BadField(f"{where}.settings={settings!r}; expected an object (the scene's render settings)")
    c2w = e.get("source_c2w")
    if not isinstance(c2w, list) or len(c2w) != 16:
        raise BadField(f"{where}.source_c2w must be 16 numbers (a row-major 4x4 camera-to-world pose)")
    for k, v in enumerate(c2w):
        _number(v, f"{where}.source_c2w[{k}]")
    _camera(e.get("camera"), f"{where}.camera")
    transform, mutation = _follow_up(e, where)
    if e.get("units", "reference") not in ("reference", "scene", "metres"):
        raise BadField(f"{where}.units={e.get('units')!r}; expected 'reference', 'scene' or 'metres'")
    score, deviation = e.get("score"), e.get("deviation")
    if status == "accepted":
        score = _number(score, f"{where}.score")
        deviation = _number(deviation, f"{where}.deviation (an accepted example)", minimum=0)
        if not isinstance(e.get("passed"), bool):
            raise BadField(f"{where}.passed={e.get('passed')!r}; expected true or false")
    else:
        if score is not None or deviation is not None:
            raise BadField(f"{where} is {status} but has a score or deviation (expected null)")
        score = deviation = math.nan
    return ExampleRecord.from_dict({**e, "transform": transform, "mutation": mutation, "score": score,
                                    "deviation": deviation, "passed": bool(e.get("passed"))})
