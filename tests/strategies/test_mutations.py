"""The DeepXplore baseline mutations: exact effects, determinism, resolution independence, shrinking."""

from __future__ import annotations

import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import find, given, settings

from pytest_n2r import strategies as m
from pytest_n2r.errors import InvalidArgument, InvalidType

images = st.tuples(st.integers(1, 64), st.integers(1, 64), st.integers(0, 2**16)).map(
    lambda hws: np.random.default_rng(hws[2]).integers(0, 256, size=(hws[0], hws[1], 3), dtype=np.uint8)
)


def changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.any(a != b, axis=2)


@settings(max_examples=60)
@given(mutation=m.any_mutation(), image=images)
def test_mutations_return_a_new_uint8_image_and_leave_the_input_alone(mutation, image):
    before = image.copy()
    out = mutation.apply(image)
    assert out.dtype == np.uint8 and out.shape == image.shape and out is not image
    np.testing.assert_array_equal(image, before)
    np.testing.assert_array_equal(mutation(image), out)  # seeded: the same image every time
    if mutation.is_identity:
        np.testing.assert_array_equal(out, image)


@settings(max_examples=60)
@given(mutation=m.any_mutation())
def test_repr_rebuilds_an_equal_mutation(mutation):
    rebuilt = eval(repr(mutation), {**vars(m)})
    assert rebuilt == mutation and hash(rebuilt) == hash(mutation)
    assert mutation.as_dict()["name"] == mutation.name and mutation.describe()


@settings(max_examples=40)
@given(levels=st.integers(-255, 255), image=images)
def test_brightness_adds_a_saturated_constant(levels, image):
    out = m.Brightness(levels).apply(image)
    expected = np.clip(image.astype(int) + levels, 0, 255)
    np.testing.assert_array_equal(out, expected)


def test_noise_patch_covers_the_stated_fraction_at_any_resolution():
    mutation = m.NoisePatch(size=0.25, x=1.0, y=0.0, seed=7)
    for h, w in [(270, 480), (1080, 1920), (100, 60)]:
        image = np.full((h, w, 3), 128, np.uint8)
        diff = changed(image, mutation.apply(image))
        rows, cols = np.nonzero(diff)
        ph, pw = round(0.25 * h), round(0.25 * w)
        # noise hits the grey 128 by chance in ~1/256^3 of the pixels per channel triple; allow a few
        assert diff.sum() > 0.99 * ph * pw and diff.sum() <= ph * pw
        assert rows.min() == 0 and rows.max() == ph - 1, "y=0 puts the patch against the top border"
        assert cols.max() == w - 1 and cols.min() == w - pw, "x=1 puts the patch against the right border"


def test_black_patches_are_black_small_and_counted():
    image = np.full((270, 480, 3), 200, np.uint8)
    mutation = m.BlackPatches(size=0.02, count=6, seed=3)
    out = mutation.apply(image)
    black = np.all(out == 0, axis=2)
    assert np.array_equal(black, changed(image, out)), "black patches only blacken"
    patch_area = round(0.02 * 270) * round(0.02 * 480)
    assert patch_area < black.sum() <= 6 * patch_area
    assert m.BlackPatches(size=0.02, count=6, seed=4).apply(image).tolist() != out.tolist()


def test_tiny_nonzero_sizes_still_change_a_pixel():
    image = np.full((10, 10, 3), 200, np.uint8)
    assert changed(image, m.BlackPatches(size=1e-6, count=1).apply(image)).sum() == 1
    assert changed(image, m.NoisePatch(size=1e-6, seed=1).apply(image)).sum() == 1


@pytest.mark.parametrize("strategy", [m.brightness(), m.noise_patch(), m.black_patches(), m.any_mutation()])
def test_no_draw_is_no_change(strategy):
    """A mutation that changes nothing compares a view with itself: a test that cannot fail."""

    @settings(database=None, max_examples=300)
    @given(mutation=strategy)
    def check(mutation: m.Mutation) -> None:
        assert not mutation.is_identity, f"{mutation!r} was drawn: it changes nothing"

    check()


@pytest.mark.parametrize(("strategy", "smallest"), [
    (m.brightness(), m.Brightness(1)), (m.any_mutation(), m.Brightness(1)),
    (m.noise_patch(), m.NoisePatch(size=0.0001, x=0.0, y=0.0)), (m.black_patches(), m.BlackPatches(size=0.00001)),
])
def test_strategies_shrink_toward_the_smallest_change(strategy, smallest):
    minimal = find(strategy, lambda mutation: True, settings=settings(database=None, max_examples=5))
    assert minimal == smallest, f"shrunk to {minimal!r}; expected {smallest!r}"


def test_shrinking_finds_the_smallest_breaking_brightness():
    """A 'SUT' that breaks at 20 grey levels or more: the reported example is exactly the threshold."""
    minimal = find(m.brightness(), lambda mu: abs(mu.levels) >= 20, settings=settings(database=None))
    assert abs(minimal.levels) == 20, minimal


@pytest.mark.parametrize(("strategy", "threshold", "step"), [
    (m.noise_patch(), 0.1234, 1e-4), (m.noise_patch(max_size=0.3, min_size=0.05), 0.2222, 1e-4),
    (m.black_patches(), 0.0123, 1e-5), (m.black_patches(max_size=0.5, count=2), 0.3456, 1e-4),
])
def test_patch_sizes_shrink_to_the_smallest_breaking_size(strategy, threshold, step):
    """docs/mutations.md: sizes shrink toward min_size; drawn as plain floats they shrank to a "simple" float
    (0.5, 0.0625) far above the threshold."""
    minimal = find(strategy, lambda mu: mu.size > threshold, settings=settings(database=None, max_examples=500))
    assert threshold < minimal.size <= threshold + step * 1.000001, (
        f"shrunk to size={minimal.size}; expected within one grid step ({step}) above {threshold}")


@pytest.mark.parametrize("min_size", [0.1234, 0.05, 0.5])
def test_any_noise_patch_failing_shrinks_to_min_size(min_size):
    minimal = find(m.noise_patch(max_size=0.5, min_size=min_size), lambda mu: True,
                   settings=settings(database=None, max_examples=50))
    assert minimal.size == min_size, f"shrunk to size={minimal.size}; expected min_size={min_size}"


def test_strategy_reprs_are_their_calls():
    assert repr(m.brightness(max_levels=30)) == "brightness(max_levels=30)"
    assert repr(m.black_patches(count=4)) == "black_patches(max_size=0.08, count=4)"
    # a relation's description keys its Hypothesis database and derandomized seed: these reprs must not drift
    assert repr(m.noise_patch()) == "noise_patch(max_size=0.5, min_size=0.0)"
    assert repr(m.black_patches()) == "black_patches(max_size=0.08)"
    assert repr(m.any_mutation()) == "any_mutation(max_noise_size=0.5, max_patch_size=0.08)"


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda: m.Brightness(300), InvalidArgument, r"levels=300 is out of range; expected an int in \[-255, 255\]"),
        (lambda: m.Brightness(0.5), InvalidType, r"levels=0\.5 must be an int"),
        (lambda: m.NoisePatch(size=-0.1), InvalidArgument, r"size=-0\.1 is out of range"),
        (lambda: m.NoisePatch(size=0.1, seed=1.5), InvalidType, r"seed=1\.5 must be an int"),
        (lambda: m.BlackPatches(size=0.1, count=100), InvalidArgument, r"count=100 is out of range"),
        (lambda: m.brightness(max_levels=256), InvalidArgument, r"max_levels=256 is out of range"),
        (lambda: m.noise_patch(max_size=0.2, min_size=0.3), InvalidArgument, r"min_size=0\.3 is out of range"),
        (lambda: m.brightness(max_levels=0), InvalidArgument, r"max_levels=0 is out of range"),
        (lambda: m.noise_patch(max_size=0.0), InvalidArgument, r"max_size=0\.0 must be > 0"),
        (lambda: m.black_patches(max_size=0.0), InvalidArgument, r"max_size=0\.0 must be > 0"),
        (lambda: m.black_patches(count=0), InvalidArgument, r"count=0 is out of range"),
        (lambda: m.any_mutation(max_patch_size=0), InvalidArgument, r"max_patch_size=0\.0 must be > 0"),
        (lambda: m.Brightness(10).apply(np.zeros((4, 4, 3), np.float32)), InvalidType, "got dtype float32"),
        (lambda: m.Brightness(10).apply(np.zeros((4, 4), np.uint8)), InvalidType, r"rgb must have shape \(H W 3\)"),
    ],
)
def test_bad_arguments_say_what_was_expected(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_mutations_are_immutable():
    mutation = m.Brightness(20)
    with pytest.raises(AttributeError):
        mutation.levels = 30  # type: ignore[misc]


def test_follow_up_view_keeps_the_geometry():
    from pytest_n2r.geometry import Camera
    from pytest_n2r.render.view import RenderedView

    camera = Camera(8, 6, 10.0, 10.0, 3.5, 2.5)
    rgb = np.full((6, 8, 3), 100, np.uint8)
    depth = np.full((6, 8), 2.0, np.float32)
    view = RenderedView(camera, np.eye(4), rgb=rgb, depth=depth, opacity=np.ones_like(depth))
    follow = m.Brightness(-100).apply_to_view(view)
    assert follow.camera is camera and follow.depth is depth and follow.opacity is view.opacity
    np.testing.assert_array_equal(follow.c2w, view.c2w)
    assert int(follow.rgb.max()) == 0 and int(view.rgb.min()) == 100
    with pytest.raises(InvalidArgument, match="rendered without rgb"):
        m.Brightness(1).apply_to_view(RenderedView(camera, np.eye(4), depth=depth))
    with pytest.raises(InvalidType, match="view must be a RenderedView, got ndarray"):
        m.Brightness(1).apply_to_view(rgb)


def test_a_mutation_that_is_not_a_dataclass_is_refused_naming_how_to_declare_it(monkeypatch):
    """A subclass without @dataclass was registered and applied, then its repr, record and mutation_from_dict failed
    with a bare "must be called with a dataclass type or instance"."""
    from typing import ClassVar

    from pytest_n2r.strategies import mutation as module

    monkeypatch.setattr(module, "_KINDS", dict(module._KINDS))  # the class registers in a copy, not for later tests

    class Undecorated(m.Mutation):
        name: ClassVar[str] = "test_undecorated"

        @property
        def is_identity(self) -> bool:
            return False

        def _apply(self, rgb):
            return 255 - rgb

        def describe(self) -> str:
            return "invert"

    expected = (r"tests\.strategies\.test_mutations\..*Undecorated is a Mutation but not a dataclass: declare it "
                r"@dataclass\(frozen=True, repr=False\)")
    with pytest.raises(InvalidType, match=expected):
        Undecorated()
    with pytest.raises(InvalidType, match=expected):
        m.mutation_from_dict({"name": "test_undecorated"})
    assert m.Brightness(3) == m.mutation_from_dict({"name": "brightness", "levels": 3})  # dataclasses still are
