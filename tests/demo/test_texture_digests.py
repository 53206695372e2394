"""A photo's texture digest from the user cache: the texels' digest, never a stale one."""

from __future__ import annotations

import os

import numpy as np
import pytest

from pytest_n2r.demo import textures
from pytest_n2r.demo.textures import Texture

RECIPE = {"tint": (0.9, 0.8, 0.7), "contrast": 1.5, "gain": 0.9, "quarter_turns": 1}


@pytest.fixture
def photo_file(tmp_path, monkeypatch):
    """The "brick" photo read from a file of this test (``.npy``), the user cache in ``tmp_path``."""
    path = tmp_path / "brick.npy"
    np.save(path, np.full((16, 24, 3), 0.25, np.float32))
    monkeypatch.setenv("N2R_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(textures, "_photo_file", lambda name: path)
    monkeypatch.setattr(textures, "sample_photo", lambda name: np.load(path))
    return path


def texel_digest(texture: Texture) -> str:
    """The digest of a texture built from the same texels as an array (hashed every time)."""
    return Texture(texture.image.copy(), texture.wrap).digest()


def test_a_photo_is_not_read_when_the_cache_holds_its_digest(photo_file, monkeypatch):
    first = Texture.photo("brick", **RECIPE)
    digest = first.digest()
    assert digest == texel_digest(first), "the cached digest is not the texels' digest"
    monkeypatch.setattr(textures, "sample_photo", lambda name: pytest.fail("the photo was read again"))
    again = Texture.photo("brick", **RECIPE)
    assert again.digest() == digest
    assert "image" not in again.__dict__, "digest() read the texels though the cache held their digest"


@pytest.mark.parametrize("new_content", [False, True], ids=["same content", "new content"])
def test_an_edited_photo_file_gets_the_digest_of_its_new_texels(photo_file, new_content):
    before = Texture.photo("brick", **RECIPE).digest()
    np.save(photo_file, np.full((16, 24, 3), 0.75 if new_content else 0.25, np.float32))  # the same size
    stat = photo_file.stat()
    os.utime(photo_file, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    edited = Texture.photo("brick", **RECIPE)
    after = edited.digest()
    assert "image" in edited.__dict__, "the digest of an edited photo file was served from the cache"
    assert after == texel_digest(edited)
    assert (after != before) == new_content, f"digest before {before}, after {after}"


def test_another_recipe_gets_its_own_digest(photo_file):
    assert Texture.photo("brick", **RECIPE).digest() != Texture.photo("brick", **{**RECIPE, "gain": 0.5}).digest()


@pytest.mark.parametrize("entry", [b"", b"not a digest", b"\xff\xfe" * 40, b"0" * 63])
def test_a_corrupt_cache_entry_is_recomputed_and_rewritten(photo_file, tmp_path, entry):
    digest = Texture.photo("brick", **RECIPE).digest()
    (cached,) = (tmp_path / "cache" / "texture-digests").iterdir()
    cached.write_bytes(entry)
    texture = Texture.photo("brick", **RECIPE)
    assert texture.digest() == digest and "image" in texture.__dict__
    assert cached.read_text() == digest, "the corrupt entry was not rewritten"


def test_a_read_texture_hashes_its_texels(photo_file):
    """Texels read (and perhaps edited in place) are hashed, not looked up."""
    Texture.photo("brick", **RECIPE).digest()  # the cache holds the digest now
    texture = Texture.photo("brick", **RECIPE)
    before = texture.digest()
    texture.image[0, 0] = 0.0
    assert texture.digest() != before, "a texture edited after its cached digest kept that digest"


def test_a_photo_texture_is_the_eager_one():
    photo = Texture.photo("coffee", wrap="clamp", contrast=1.2)
    assert np.array_equal(photo.image, textures._photo_image("coffee", (1.0, 1.0, 1.0), 1.0, 1.2, 0))
    assert [level.shape for level in photo.levels] == [level.shape for level in Texture(photo.image, "clamp").levels]
    with pytest.raises(AttributeError, match="has no attribute 'nothing'"):
        photo.nothing  # noqa: B018


def test_a_photo_under_another_wrap_mode_gets_its_own_digest(photo_file):
    """The wrap mode is part of a texture's digest: a cached digest of the mirrored photo must not be served for the
    clamped one (two scenes would share a content hash, and so their renders)."""
    mirrored = Texture.photo("brick", **RECIPE, wrap="mirror").digest()
    clamped = Texture.photo("brick", **RECIPE, wrap="clamp")
    assert clamped.digest() == texel_digest(clamped) != mirrored, "the clamped photo got the mirrored one's digest"


def test_each_mip_level_is_the_2x2_mean_of_the_one_above():
    """The levels are not in the digest (the texels are): a level filtered wrongly would change far surfaces' colours
    under the same content hash."""
    rng = np.random.default_rng(0)
    texture = Texture(rng.uniform(0.0, 1.0, (37, 52, 3)).astype(np.float32))
    assert [level.shape[:2] for level in texture.levels] == [(37, 52), (18, 26), (9, 13), (4, 6)]
    for k, (above, level) in enumerate(zip(texture.levels, texture.levels[1:])):
        h, w = level.shape[:2]
        mean = above[:2 * h, :2 * w].reshape(h, 2, w, 2, 3).mean(axis=(1, 3))
        np.testing.assert_allclose(level, mean, rtol=0, atol=1e-6, err_msg=f"mip level {k + 1} is not the 2x2 mean "
                                                                           f"of level {k}")
