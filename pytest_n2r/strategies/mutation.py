"""2-D image mutations: the DeepXplore baselines the paper compares rendered transforms against.

- **m1** :class:`Brightness`: a constant number of grey levels added to every channel (camera
  over-/under-exposure);
- **m2** :class:`NoisePatch`: one large rectangle of uniform random pixels (a sensor or cable fault);
- **m3** :class:`BlackPatches`: several small black rectangles (dirt on the lens).

Convention
----------
- Images are H×W×3 ``uint8`` RGB (what scenes render); a mutation returns a new image and never
  changes its input. The follow-up of a mutation relation is the mutated source render at the same
  pose, so depth and opacity are unchanged.
- Every patch size and position is a **fraction of the image size**, so one mutation means the same thing at
  any resolution: a patch of ``size=0.25`` is a quarter of the width by a quarter of the height. A
  position ``x=0`` puts a patch against the left border, ``x=1`` against the right (likewise ``y``,
  top to bottom); patches always lie inside the image.
- Random pixels and positions come from ``numpy.random.default_rng(seed)``: the same mutation gives
  the same image, bit for bit.
- The Hypothesis strategies that draw them (:mod:`pytest_n2r.strategies.mutation_strategies`) shrink
  toward **no change**: a failing example is reported as the smallest mutation that still breaks the SUT.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Callable
from dataclasses import Field, dataclass, fields, is_dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from .._validation import check_array, check_int, check_range
from ..errors import InvalidArgument, InvalidType
from .follow_up import FollowUp

if TYPE_CHECKING:
    from typing_extensions import Self  # typing.Self from Python 3.11

    from ..render.view import RenderedView
    from ..scene.base import Scene

__all__ = [
    "MAX_SEED",
    "MAX_COUNT",
    "Mutation",
    "Brightness",
    "NoisePatch",
    "BlackPatches",
    "mutation_from_dict",
    "is_registered",
]

#: Largest seed of a mutation's random generator.
MAX_SEED = 2**32 - 1
#: Most black patches one :class:`BlackPatches` may draw.
MAX_COUNT = 64


def _check_image(rgb: Any) -> np.ndarray:
    arr = check_array("rgb", rgb, "H W 3")
    if arr.dtype != np.uint8:
        raise InvalidType(f"rgb must be an H×W×3 uint8 RGB image, got dtype {arr.dtype}")
    return arr


def _patch_pixels(size: float, extent: int) -> int:
    """Pixels of a patch that is ``size`` of ``extent``: at least 1 when ``size > 0``, at most ``extent``."""
    return 0 if size == 0 else min(extent, max(1, round(size * extent)))


def _plain(owner: str, field: str, value: Any) -> Any:
    """``value`` as plain JSON data (numpy scalars as Python numbers); other values are refused."""
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (list, tuple)):
        return type(value)(_plain(owner, field, v) for v in value)
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return {k: _plain(owner, field, v) for k, v in value.items()}
    raise InvalidType(f"{owner}.{field}={value!r} cannot be written to a record: a mutation's fields must be "
                      "numbers, strings, booleans, None, or lists and str-keyed dicts of them")


def _fields_of(cls: type[Mutation]) -> tuple[Field, ...]:
    """The parameters (dataclass fields) of a mutation class; raises naming the class when it is not a dataclass (a
    dataclass decorator runs after ``__init_subclass__``, so this is checked when the class is first used)."""
    if not is_dataclass(cls):
        raise InvalidType(f"{cls.__module__}.{cls.__qualname__} is a Mutation but not a dataclass: declare it "
                          "@dataclass(frozen=True, repr=False), with its parameters as fields, so that its repr, "
                          "its record (as_dict) and mutation_from_dict can list them")
    return fields(cls)


#: Mutation classes by ``name``, for :func:`mutation_from_dict` (every subclass with a name registers).
_KINDS: dict[str, type[Mutation]] = {}


class Mutation(FollowUp):
    """An immutable, seeded image mutation: ``apply(rgb) -> rgb`` on H×W×3 uint8 RGB images; as a
    follow-up, the source render mutated at the same pose.

    ``repr`` rebuilds the constructor call; :meth:`describe` says what it does in words. A mutation of
    your own is a frozen dataclass subclass (``@dataclass(frozen=True, repr=False)``) with a ``name``
    (registered, so :func:`mutation_from_dict` rebuilds it from an example record while the class is
    imported), ``_apply``, ``is_identity`` and ``describe``; one that is not a dataclass is refused
    (:class:`~pytest_n2r.errors.InvalidType`) when it is first made.
    """

    #: Short name used in reports and records (``"brightness"``).
    name: ClassVar[str]
    moves_camera: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        name = cls.__dict__.get("name")
        if name is None:  # a base of named mutations (abstract or not): refused only if drawn (as_dict)
            return
        if not isinstance(name, str) or not name:
            raise InvalidType(f"{cls.__qualname__}.name={name!r} must be a non-empty str")
        taken = _KINDS.get(name)
        if taken is not None and (taken.__module__, taken.__qualname__) != (cls.__module__, cls.__qualname__):
            if taken.__module__ == __name__:
                raise InvalidArgument(f"{cls.__qualname__}.name={name!r} is the built-in {taken.__name__}'s; "
                                      "give the mutation another name")
            raise InvalidArgument(f"{cls.__module__}.{cls.__qualname__}.name={name!r} is already the name of "
                                  f"{taken.__module__}.{taken.__qualname__}; a record rebuilds its mutation by "
                                  "name, so give one of the two classes another name")
        _KINDS[name] = cls  # the same module and class again: a reload

    def __new__(cls, *args: Any, **kwargs: Any) -> Self:
        self = super().__new__(cls)
        _fields_of(cls)  # a mutation of one's own that is not a dataclass is refused here, before it is drawn
        return self

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        return self.apply(rgb)

    def apply(self, rgb: np.ndarray) -> np.ndarray:
        """The mutated copy of ``rgb`` (H×W×3 uint8 RGB); the input is not modified."""
        rgb = _check_image(rgb)
        return rgb.copy() if self.is_identity else self._apply(rgb)

    def apply_to_view(self, view: RenderedView) -> RenderedView:
        """The follow-up view of a mutation relation: ``view`` with its ``rgb`` mutated; pose, camera,
        depth and opacity unchanged (a mutation does not move the camera)."""
        from ..render.view import RenderedView

        if not isinstance(view, RenderedView):
            raise InvalidType(f"view must be a RenderedView, got {type(view).__name__}")
        return replace(view, rgb=self.apply(view.output("rgb")))

    def follow_view(self, source: RenderedView, scene: Scene,
                    render: Callable[[np.ndarray], RenderedView]) -> RenderedView:
        """:meth:`apply_to_view` of ``source``: nothing is rendered."""
        return self.apply_to_view(source)

    def record_fields(self) -> dict[str, Any]:
        return {"transform": None, "mutation": self.as_dict()}

    def explain(self, scene: Scene, note: str) -> list[str]:
        return [f"  follow-up:  the source render mutated by {self.describe()}  ({note or 'minimal after shrinking'})"]

    @abstractmethod
    def _apply(self, rgb: np.ndarray) -> np.ndarray:
        """The mutated image as a new array (``rgb`` is a checked H×W×3 uint8 image; leave it alone)."""

    @property
    @abstractmethod
    def is_identity(self) -> bool:
        """True when the mutation changes no pixel of any image."""

    @abstractmethod
    def describe(self) -> str:
        """Words for reports: ``"brightness +30 levels (+11.8% of full scale)"``."""

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-ready parameters, with the mutation's ``name`` (numpy scalars become Python numbers)."""
        if getattr(self, "name", None) is None:
            cls = type(self)
            raise InvalidArgument(f"{cls.__qualname__} has no name: a Mutation that is drawn needs a short name for "
                                  f"reports and records, e.g. name: ClassVar[str] = {cls.__name__.lower()!r}")
        return {"name": self.name, **{f.name: _plain(type(self).__name__, f.name, getattr(self, f.name))
                                      for f in fields(self)}}  # type: ignore[arg-type]

    def __repr__(self) -> str:
        args = ", ".join(f"{f.name}={getattr(self, f.name)!r}" for f in fields(self))  # type: ignore[arg-type]
        return f"{type(self).__name__}({args})"


@dataclass(frozen=True, repr=False)
class Brightness(Mutation):
    """m1: add ``levels`` grey levels (an int in [-255, 255]; 26 ≈ +10 % of full scale) to every channel,
    saturating at 0 and 255."""

    levels: int = 0
    name: ClassVar[str] = "brightness"

    def __post_init__(self) -> None:
        object.__setattr__(self, "levels", check_int("levels", self.levels, -255, 255))

    @property
    def is_identity(self) -> bool:
        return self.levels == 0

    def _apply(self, rgb: np.ndarray) -> np.ndarray:
        import cv2

        table = np.clip(np.arange(256) + self.levels, 0, 255).astype(np.uint8)
        return cv2.LUT(np.ascontiguousarray(rgb), table)

    def describe(self) -> str:
        return f"brightness {self.levels:+d} levels ({self.levels / 255 * 100:+.1f}% of full scale)"


@dataclass(frozen=True, repr=False)
class NoisePatch(Mutation):
    """m2: one rectangle of uniform random pixels, ``size`` of the width by ``size`` of the height
    (``size`` in [0, 1]), placed at relative position ``(x, y)`` in [0, 1] (see the module conventions)."""

    size: float = 0.0
    x: float = 0.5
    y: float = 0.5
    seed: int = 0
    name: ClassVar[str] = "noise_patch"

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", check_range("size", self.size, 0.0, 1.0) + 0.0)
        object.__setattr__(self, "x", check_range("x", self.x, 0.0, 1.0) + 0.0)
        object.__setattr__(self, "y", check_range("y", self.y, 0.0, 1.0) + 0.0)
        object.__setattr__(self, "seed", check_int("seed", self.seed, 0, MAX_SEED))

    @property
    def is_identity(self) -> bool:
        return self.size == 0.0

    def _apply(self, rgb: np.ndarray) -> np.ndarray:
        out = rgb.copy()
        h, w = out.shape[:2]
        ph, pw = _patch_pixels(self.size, h), _patch_pixels(self.size, w)
        top, left = round(self.y * (h - ph)), round(self.x * (w - pw))
        out[top:top + ph, left:left + pw] = np.random.default_rng(self.seed).integers(
            0, 256, size=(ph, pw, 3), dtype=np.uint8)
        return out

    def describe(self) -> str:
        return (f"noise patch {self.size * 100:.0f}%×{self.size * 100:.0f}% of the image at "
                f"({self.x:.2f}, {self.y:.2f}), seed {self.seed}")


@dataclass(frozen=True, repr=False)
class BlackPatches(Mutation):
    """m3: ``count`` black rectangles (default 6), each ``size`` of the width by ``size`` of the height
    (``size`` in [0, 1]), at positions drawn uniformly from ``seed`` (they may overlap)."""

    size: float = 0.0
    count: int = 6
    seed: int = 0
    name: ClassVar[str] = "black_patches"

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", check_range("size", self.size, 0.0, 1.0) + 0.0)
        object.__setattr__(self, "count", check_int("count", self.count, 0, MAX_COUNT))
        object.__setattr__(self, "seed", check_int("seed", self.seed, 0, MAX_SEED))

    @property
    def is_identity(self) -> bool:
        return self.size == 0.0 or self.count == 0

    def positions(self) -> np.ndarray:
        """``(count, 2)`` relative ``(x, y)`` positions in [0, 1] of the patches."""
        return np.random.default_rng(self.seed).random((self.count, 2))

    def _apply(self, rgb: np.ndarray) -> np.ndarray:
        out = rgb.copy()
        h, w = out.shape[:2]
        ph, pw = _patch_pixels(self.size, h), _patch_pixels(self.size, w)
        for x, y in self.positions():
            top, left = round(y * (h - ph)), round(x * (w - pw))
            out[top:top + ph, left:left + pw] = 0
        return out

    def describe(self) -> str:
        return f"{self.count} black patches of {self.size * 100:.1f}%×{self.size * 100:.1f}%, seed {self.seed}"


def is_registered(name: str) -> bool:
    """Whether a mutation class named ``name`` is defined (built in, or a subclass whose module was imported).

    >>> is_registered("brightness"), is_registered("no such mutation")
    (True, False)
    """
    return name in _KINDS


def mutation_from_dict(data: dict[str, Any]) -> Mutation:
    """The mutation of :meth:`Mutation.as_dict` (``{"name": "brightness", "levels": 30}``), validated; the
    name is a built-in one or that of an imported :class:`Mutation` subclass.

    >>> mutation_from_dict({"name": "brightness", "levels": 30})
    Brightness(levels=30)
    """
    if not isinstance(data, dict) or not isinstance(data.get("name"), str):
        raise InvalidArgument(f"mutation={data!r}: expected a dict with 'name' one of {sorted(_KINDS)}")
    if data["name"] not in _KINDS:
        raise InvalidArgument(f"mutation={data!r}: no mutation named {data['name']!r} is defined (known: "
                              f"{sorted(_KINDS)}); a mutation of your own is known once the module that defines "
                              "its class is imported")
    cls = _KINDS[data["name"]]
    params = {k: v for k, v in data.items() if k != "name"}
    unknown = sorted(set(params) - {f.name for f in _fields_of(cls)})
    if unknown:
        raise InvalidArgument(f"mutation={data!r}: {cls.__name__} has no parameter(s) {unknown}")
    return cls(**params)
