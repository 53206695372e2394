"""The render cache: memory and disk hits, per-output storage, eviction, corruption, concurrent writers."""

from __future__ import annotations

import ast
import multiprocessing
import os
from pathlib import Path

import numpy as np
import pytest

from pytest_n2r import InvalidArgument, Transform
from pytest_n2r.scene.render_cache import RenderCache, parse_size, render_key

from ..plugin.fakescene import PlaneScene

ALL = ("rgb", "depth", "opacity")


def _pose(scene, yaw=0.0):
    return Transform(yaw=yaw).apply(scene.views[0].c2w)


def test_a_second_cache_on_the_same_directory_renders_nothing(tmp_path):
    scene = PlaneScene()
    camera = scene.views[0].camera
    first = RenderCache(tmp_path)
    views = [first.render(scene, _pose(scene, yaw), camera, ALL) for yaw in (0, 3, 6)]
    assert scene.calls == 3 and first.stats.renders == 3
    again = first.render(scene, _pose(scene, 3), camera, ALL)
    assert scene.calls == 3 and first.stats.memory_hits == 3, first.stats
    second = RenderCache(tmp_path)
    for yaw, view in zip((0, 3, 6), views):
        cached = second.render(scene, _pose(scene, yaw), camera, ALL)
        for name in ALL:
            np.testing.assert_array_equal(getattr(cached, name), getattr(view, name))
    assert scene.calls == 3, f"the disk cache missed: {second.stats}"
    assert second.stats.disk_hits == 9 and second.stats.renders == 0
    assert again.rgb.flags.writeable is False, "cached arrays are shared and must be read-only"


def test_a_render_of_edited_rendering_code_is_not_read_and_other_edits_keep_the_renders(tmp_path, monkeypatch):
    """A renderer edited in a checkout whose version did not move (a git install at another commit) must not be
    given the old code's pictures; an edit outside the rendering code keeps them."""
    from pytest_n2r.scene import render_cache

    scene = PlaneScene()
    camera = scene.views[0].camera
    RenderCache(tmp_path).render(scene, _pose(scene), camera, "rgb")
    original = render_cache.source_digest
    monkeypatch.setattr(render_cache, "source_digest", lambda *parts: "edited" if not parts else original(*parts))
    kept = RenderCache(tmp_path)
    kept.render(scene, _pose(scene), camera, "rgb")
    assert kept.stats.disk_hits == 1 and scene.calls == 1, f"an edit outside the renderers re-rendered: {kept.stats}"
    monkeypatch.setattr(render_cache, "source_digest",
                        lambda *parts: "edited renderer" if parts == render_cache.RENDERING_CODE else original(*parts))
    edited = RenderCache(tmp_path)
    edited.render(scene, _pose(scene), camera, "rgb")
    assert edited.stats.renders == 1 and scene.calls == 2, f"the old renderer's picture was read: {edited.stats}"


def test_only_missing_outputs_are_rendered(tmp_path, monkeypatch):
    scene = PlaneScene()
    asked = []
    original = scene._render
    monkeypatch.setattr(scene, "_render",
                        lambda c2w, cam, outputs: asked.append(outputs) or original(c2w, cam, outputs))
    cache = RenderCache(tmp_path)
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    view = cache.render(scene, _pose(scene), scene.views[0].camera, ("rgb", "opacity"))
    assert asked == [("rgb",), ("opacity",)]
    assert view.rgb is not None and view.opacity is not None and view.depth is None


def test_a_keyed_render_names_itself_by_its_render_key(tmp_path):
    scene = PlaneScene()
    camera = scene.views[0].camera
    cache = RenderCache(tmp_path)
    for _ in range(2):  # rendered, then from memory
        view, key = cache.render_keyed(scene, _pose(scene), camera, "rgb")
        assert key == render_key(scene, _pose(scene), camera), "the key returned is not the render's key"
        assert view.rgb is not None


def test_the_key_changes_with_everything_that_changes_pixels():
    scene, other = PlaneScene(), PlaneScene(texture="ramp")
    camera = scene.views[0].camera
    base = render_key(scene, _pose(scene), camera)
    assert render_key(scene, _pose(scene), camera) == base
    assert render_key(other, _pose(scene), camera) != base
    assert render_key(scene, _pose(scene, 1e-9), camera) != base
    assert render_key(scene, _pose(scene), camera.resized(48, 36)) != base
    scene.renderer_version = "another renderer"
    assert render_key(scene, _pose(scene), camera) != base


@pytest.mark.parametrize("damage", [
    lambda data: data[:40],  # the header cut
    lambda data: b"",  # renamed into place, then a crash before its blocks reached the disk
    lambda data: data[:6],  # the magic alone: numpy reads to the end of the file and stops
    lambda data: b"PK\x03\x04" + data[4:],  # what np.load would open as a zip archive
], ids=["header cut", "empty", "magic alone", "zip magic"])
def test_a_corrupt_entry_is_rendered_again(tmp_path, damage):
    scene = PlaneScene()
    camera = scene.views[0].camera
    RenderCache(tmp_path).render(scene, _pose(scene), camera, "rgb")
    (entry,) = (tmp_path / "renders").glob("*/*.rgb.npy")
    entry.write_bytes(damage(entry.read_bytes()))
    view = RenderCache(tmp_path).render(scene, _pose(scene), camera, "rgb")
    assert scene.calls == 2, f"the damaged entry was not rendered again ({scene.calls} renders)"
    assert view.rgb.shape == (72, 96, 3)
    view = RenderCache(tmp_path).render(scene, _pose(scene), camera, "rgb")
    assert scene.calls == 2, "the entry rendered again was not stored in place of the damaged one"


def test_an_entry_cut_short_in_its_pixels_is_rendered_again(tmp_path):
    scene = PlaneScene()
    camera = scene.views[0].camera
    RenderCache(tmp_path).render(scene, _pose(scene), camera, "depth")
    (entry,) = (tmp_path / "renders").glob("*/*.depth.npy")
    entry.write_bytes(entry.read_bytes()[:-8])  # the header intact, two pixels missing
    view = RenderCache(tmp_path).render(scene, _pose(scene), camera, "depth")
    assert scene.calls == 2 and view.depth.shape == (72, 96)


def test_an_entry_with_another_header_is_read_as_numpy_reads_it(tmp_path):
    """Entries are read without numpy's header parser when their header is a render's; any other valid
    ``.npy`` file (here big-endian floats) is read by ``np.load``, and given in the render's dtype."""
    scene = PlaneScene()
    camera = scene.views[0].camera
    depth = RenderCache(tmp_path).render(scene, _pose(scene), camera, "depth").depth
    (entry,) = (tmp_path / "renders").glob("*/*.depth.npy")
    np.save(entry, depth.astype(">f4"))
    cached = RenderCache(tmp_path).render(scene, _pose(scene), camera, "depth").depth
    assert scene.calls == 1 and cached.dtype == np.float32 and not cached.flags.writeable
    np.testing.assert_array_equal(cached, depth)


def _nan_like(value):
    out = value.astype(np.float32)
    out[3, 4] = np.nan
    return out


@pytest.mark.parametrize("output, plant", [
    ("rgb", lambda value: np.full((3, 3), np.nan)),  # another shape and dtype
    ("rgb", lambda value: value[:, :-1]),  # another width
    ("rgb", lambda value: value.astype(np.float32)),  # the pixels as floats
    ("depth", lambda value: value.astype(np.int32)),
    ("depth", lambda value: value.T.copy()),  # H and W swapped
    ("depth", _nan_like),
    ("opacity", lambda value: np.full(value.shape, np.inf, np.float32)),
    ("opacity", lambda value: value[..., None].copy()),
])
def test_an_entry_that_is_not_the_render_asked_for_is_rendered_again(tmp_path, output, plant):
    scene = PlaneScene()
    camera = scene.views[0].camera
    value = getattr(RenderCache(tmp_path).render(scene, _pose(scene), camera, output), output)
    (entry,) = (tmp_path / "renders").glob(f"*/*.{output}.npy")
    np.save(entry, plant(value))
    again = getattr(RenderCache(tmp_path).render(scene, _pose(scene), camera, output), output)
    assert scene.calls == 2, "a planted entry was handed out as the render"
    np.testing.assert_array_equal(again, value)
    RenderCache(tmp_path).render(scene, _pose(scene), camera, output)
    assert scene.calls == 2, "the entry rendered again was not stored in place of the planted one"


@pytest.mark.parametrize("header", [
    "{'descr': '<f4', 'fortran_order': True, 'shape': (100000000000,), }",
    "{'descr': '<i8', 'fortran_order': False, 'shape': (100000000000, 3), }",
])
def test_an_entry_whose_header_claims_more_than_the_file_holds_is_rendered_again(tmp_path, header):
    scene = PlaneScene()
    camera = scene.views[0].camera
    RenderCache(tmp_path).render(scene, _pose(scene), camera, "rgb")
    (entry,) = (tmp_path / "renders").glob("*/*.rgb.npy")
    header += " " * (-(10 + len(header) + 1) % 64) + "\n"
    entry.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + bytes(16))
    view = RenderCache(tmp_path).render(scene, _pose(scene), camera, "rgb")
    assert scene.calls == 2 and view.rgb.shape == (72, 96, 3)
    assert entry.read_bytes()[:6] == b"\x93NUMPY" and len(entry.read_bytes()) > 72 * 96 * 3, "not replaced"


def test_trimming_never_deletes_through_a_link(tmp_path):
    scene = PlaneScene()
    camera = scene.views[0].camera
    victim = tmp_path / "elsewhere"
    victim.mkdir()
    np.save(victim / "precious.npy", np.zeros(1000))
    (victim / "notes.json").write_text("{}")
    for name in ("precious.npy", "notes.json"):
        os.utime(victim / name, (1, 1))
    cache_dir = tmp_path / "cache"
    cache = RenderCache(cache_dir)
    cache.render(scene, _pose(scene), camera, "rgb")
    (cache_dir / "decisions").mkdir()
    (cache_dir / "renders" / "zz").symlink_to(victim)
    (cache_dir / "decisions" / "zz").symlink_to(victim)
    (cache_dir / "renders" / "ab").mkdir()
    (cache_dir / "renders" / "ab" / "ab.rgb.npy").symlink_to(victim / "precious.npy")
    cache.disk_bytes = 100
    assert cache.trim() > 0
    assert sorted(p.name for p in victim.iterdir()) == ["notes.json", "precious.npy"]
    own = [p for p in (cache_dir / "renders").glob("*/*.npy") if not (p.is_symlink() or p.parent.is_symlink())]
    assert own == [], "the cache's own entry was not evicted"


def test_disk_cap_evicts_least_recently_used(tmp_path):
    scene = PlaneScene()
    camera = scene.views[0].camera
    one = camera.width * camera.height * 3 + 128  # one rgb entry with its .npy header
    cache = RenderCache(tmp_path, disk_bytes=4 * one)
    for yaw in range(8):
        cache.render(scene, _pose(scene, yaw), camera, "rgb")
    assert cache.disk_usage() <= 4 * one, cache.disk_usage()
    assert len(list((tmp_path / "renders").glob("*/*.npy"))) >= 2
    assert (tmp_path / "CACHEDIR.TAG").exists() and (tmp_path / ".gitignore").read_text().endswith("*\n")


def test_memory_cap_drops_oldest_first():
    scene = PlaneScene()
    camera = scene.views[0].camera
    cache = RenderCache(None, memory_bytes=2 * camera.width * camera.height * 3)
    for yaw in (0, 1, 2):
        cache.render(scene, _pose(scene, yaw), camera, "rgb")
    cache.render(scene, _pose(scene, 2), camera, "rgb")
    assert scene.calls == 3
    cache.render(scene, _pose(scene, 0), camera, "rgb")
    assert scene.calls == 4, "the oldest entry should have been dropped"


def test_clear_forgets_disk_and_memory(tmp_path):
    scene = PlaneScene()
    cache = RenderCache(tmp_path)
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    cache.clear()
    assert not (tmp_path / "renders").exists()
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    assert scene.calls == 2


def _worker(directory: str, yaws: list[float]) -> None:
    scene = PlaneScene()
    cache = RenderCache(directory)
    for yaw in yaws:
        cache.render(scene, _pose(scene, yaw), scene.views[0].camera, ALL)


def test_concurrent_writers_leave_only_whole_files(tmp_path):
    yaws = [float(y) for y in range(6)]
    ctx = multiprocessing.get_context("fork")
    procs = [ctx.Process(target=_worker, args=(str(tmp_path), yaws)) for _ in range(3)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
    assert all(p.exitcode == 0 for p in procs), [p.exitcode for p in procs]
    assert not [f for f in (tmp_path / "renders").rglob("*") if f.name.endswith(".tmp")]
    scene = PlaneScene()
    cache = RenderCache(tmp_path)
    for yaw in yaws:
        view = cache.render(scene, _pose(scene, yaw), scene.views[0].camera, ALL)
        np.testing.assert_array_equal(view.rgb, scene.render(_pose(scene, yaw), scene.views[0].camera).rgb)
    assert cache.stats.renders == 0


@pytest.mark.parametrize(("text", "expected"), [("2GiB", 2 * 2**30), ("512mb", 512 * 2**20), ("100", 100),
                                                 ("1.5k", 1536)])
def test_parse_size(text, expected):
    assert parse_size(text) == expected


def test_parse_size_names_the_option():
    with pytest.raises(InvalidArgument, match=r"n2r_cache_size='lots' is not a size"):
        parse_size("lots", "n2r_cache_size")



def test_a_decision_is_kept_on_disk_beside_the_renders(tmp_path):
    key = "ab" + "0" * 62
    assert RenderCache(None).decision(key) is None and RenderCache(tmp_path).decision(key) is None
    RenderCache(None).put_decision(key, {"valid": True})  # a memory-only cache keeps none
    RenderCache(tmp_path).put_decision(key, {"valid": False, "reason": "empty view"})
    assert RenderCache(tmp_path).decision(key) == {"valid": False, "reason": "empty view"}
    path = RenderCache(tmp_path)._decision_path(key)
    assert path.is_file() and path.parent.parent == tmp_path / "decisions"
    path.write_text('{"valid": tr')  # torn: decided again, and the file goes
    assert RenderCache(tmp_path).decision(key) is None and not path.exists()
    path.write_text("[" * 100000 + "]" * 100000)  # nested too deep for the JSON parser: the same
    assert RenderCache(tmp_path).decision(key) is None and not path.exists()
    cache = RenderCache(tmp_path)
    cache.put_decision(key, {"valid": True})
    cache.clear()
    assert cache.decision(key) is None and not (tmp_path / "decisions").exists()


def test_a_decision_made_by_other_code_is_not_read(tmp_path, monkeypatch):
    from pytest_n2r.scene import render_cache

    key = "cd" + "0" * 62
    RenderCache(tmp_path).put_decision(key, {"valid": True})
    assert len(render_cache.source_digest()) == 64 and render_cache.source_digest() == render_cache.source_digest()
    monkeypatch.setattr(render_cache, "source_digest", lambda: "an edited checkout")
    assert RenderCache(tmp_path).decision(key) is None, "a decision of the old code was read by the edited one"
    RenderCache(tmp_path).put_decision(key, {"valid": False})
    assert RenderCache(tmp_path).decision(key) == {"valid": False}


def test_trimming_evicts_the_decisions_older_than_the_renders_it_evicts(tmp_path):
    scene = PlaneScene()
    camera = scene.views[0].camera
    one = camera.width * camera.height * 3 + 128
    cache = RenderCache(tmp_path, disk_bytes=100 * one)
    old, new = "a" * 64, "b" * 64
    cache.put_decision(old, {"valid": True})
    for yaw in range(4):
        cache.render(scene, _pose(scene, yaw), camera, "rgb")
    cache.put_decision(new, {"valid": True})
    renders = sorted((tmp_path / "renders").glob("*/*.npy"))
    for age, path in enumerate([cache._decision_path(old), *renders]):
        os.utime(path, (1000.0 + age, 1000.0 + age))  # the old decision, then the renders, oldest first
    cache.disk_bytes = 2 * one
    assert cache.trim() > 0
    assert cache.decision(old) is None and cache.decision(new) == {"valid": True}


def _users_folder(folder):
    """A folder of the user's that happens to hold ``renders/`` and ``decisions/``, and a .gitignore of its own."""
    for sub, name in (("renders/ab", "mine.npy"), ("decisions/cd", "mine.json")):
        (folder / sub).mkdir(parents=True)
        (folder / sub / name).write_bytes(b"\x93NUMPY the user's own" * 100)
        os.utime(folder / sub / name, (1, 1))  # older than any render: the first an LRU trim would delete
    (folder / ".gitignore").write_text("build/\n")
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_a_folder_of_the_users_is_never_tagged_trimmed_nor_cleared(tmp_path):
    scene = PlaneScene()
    before = _users_folder(tmp_path)
    cache = RenderCache(tmp_path, disk_bytes=100)
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    cache.disk_bytes = 1
    assert cache.trim() == 0, "trimmed in a folder pytest-n2r did not make"
    with pytest.raises(InvalidArgument, match=rf"{tmp_path} is not a pytest-n2r render cache \(no CACHEDIR\.TAG "
                                              r"written by pytest-n2r\) and holds decisions, renders; "
                                              r"nothing was deleted"):
        cache.clear()
    assert (tmp_path / ".gitignore").read_text() == "build/\n", "the folder's own .gitignore was overwritten"
    assert not (tmp_path / "CACHEDIR.TAG").exists(), "a folder of the user's was tagged: backup tools skip it"
    after = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert set(before) <= set(after), f"deleted: {set(before) - set(after)}"


def test_a_cache_folder_the_user_made_with_a_gitignore_is_tagged_and_keeps_it(tmp_path):
    """A folder holding only a ``.gitignore`` (made for the cache) was refused as the user's, or, before the folder
    test, had its ``.gitignore`` replaced by pytest-n2r's."""
    (tmp_path / "cache" / "kernel-locks").mkdir(parents=True)  # a first render's lock comes before the first store
    (tmp_path / "cache" / ".gitignore").write_text("# mine\n*\n!README\n")
    cache = RenderCache(tmp_path / "cache")
    scene = PlaneScene()
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    assert (tmp_path / "cache" / "CACHEDIR.TAG").read_text() == ("Signature: 8a477f597d28d172789f06886806bc55\n"
                                                                "# pytest-n2r render cache\n"), "not tagged"
    cache.put_decision("ab" + "0" * 62, {"valid": True})
    assert (tmp_path / "cache" / ".gitignore").read_text() == "# mine\n*\n!README\n", "a .gitignore was replaced"
    cache.clear()
    assert not (tmp_path / "cache" / "renders").exists() and not (tmp_path / "cache" / "decisions").exists()


def test_clear_and_trim_of_a_directory_another_tool_tagged_delete_nothing(tmp_path):
    (tmp_path / "CACHEDIR.TAG").write_text("Signature: 8a477f597d28d172789f06886806bc55\n# made by another tool\n")
    (tmp_path / "renders" / "ab").mkdir(parents=True)
    np.save(tmp_path / "renders" / "ab" / "theirs.npy", np.zeros(1000))
    cache = RenderCache(tmp_path, disk_bytes=1)
    assert cache.trim() == 0
    with pytest.raises(InvalidArgument, match=r"holds CACHEDIR\.TAG, renders; nothing was deleted"):
        cache.clear()
    assert (tmp_path / "renders" / "ab" / "theirs.npy").exists()


def test_a_render_key_names_the_exact_pose():
    """Guards against hashing the pose in float32: a pose one float64 step away was given the other's render."""
    scene = PlaneScene()
    camera = scene.views[0].camera
    c2w = _pose(scene)
    c2w[0, 3] = 1.2345
    nudged = c2w.copy()
    nudged[0, 3] = np.nextafter(1.2345, np.inf)
    assert render_key(scene, c2w, camera) != render_key(scene, nudged, camera), "a float64 step: same render key"


def _imported_subpackages(path: Path, package: Path) -> set[str]:
    """The pytest_n2r subpackages (folders) that the module ``path`` imports from, relative imports resolved."""
    parts = list(path.relative_to(package.parent).with_suffix("").parts)[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = parts[:len(parts) - node.level + 1] if node.level else []
            names = (base + (node.module.split(".") if node.module else []))
            names = [n for n in names if n]
            targets = [names + [alias.name] for alias in node.names]
        elif isinstance(node, ast.Import):
            targets = [alias.name.split(".") for alias in node.names]
        else:
            continue
        for target in targets:
            if len(target) > 1 and target[0] == package.name and (package / target[1]).is_dir():
                found.add(target[1])
    return found


def test_the_rendering_code_covers_every_scene_class_and_renderer():
    """Guards against a subpackage that makes pixels missing from RENDERING_CODE (``splats`` dropped): an edit of
    the splat renderer in a checkout was handed the old code's pictures from the render cache."""
    from pytest_n2r.scene import render_cache

    package = Path(render_cache.__file__).resolve().parents[1]
    scene_modules = []
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef) and any(ast.unparse(b).split(".")[-1] == "Scene" for b in node.bases):
                scene_modules.append(path)
    renderers = sorted((package / "render").glob("*.py"))
    assert len(scene_modules) >= 3 and renderers, f"the test needs the scene classes: {scene_modules}"
    needed = {path.relative_to(package).parts[0] for path in scene_modules + renderers}
    for path in renderers:
        needed |= _imported_subpackages(path, package)
    assert {"splats", "field", "demo", "render"} <= needed, f"the derivation missed a renderer: {sorted(needed)}"
    missing = needed - set(render_cache.RENDERING_CODE)
    assert not missing, f"subpackages that make pixels but do not key renders: {sorted(missing)}"
