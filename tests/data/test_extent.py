"""Reference length and bounds from sparse points; triangulation and its filters; atomic writes."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.data import atomic
from pytest_n2r.data.atomic import atomic_write_chunks, atomic_write_text
from pytest_n2r.data.extent import reference_length, scene_bounds, seen_depths
from pytest_n2r.data.triangulate import neighbour_pairs, triangulate_views
from pytest_n2r.errors import IngestError, InvalidArgument
from pytest_n2r.geometry import Camera, Transform

CAM = Camera(100, 80, 100.0, 100.0, 49.5, 39.5)


def test_only_points_in_front_and_inside_the_image_count():
    points = np.array([
        [0.0, 0.0, 2.0],     # centre, depth 2
        [0.0, 0.0, 4.0],     # centre, depth 4
        [10.0, 0.0, 2.0],    # far outside the image (u = 549.5)
        [0.0, 0.0, -3.0],    # behind
        [0.99, 0.0, 2.0],    # u = 49.5 + 49.5 = 99.0, inside the last column
    ])
    depths, seen = seen_depths(points, [CAM], [np.eye(4)])
    assert sorted(depths.tolist()) == [2.0, 2.0, 4.0]
    assert seen.tolist() == [True, True, False, False, True]
    assert reference_length(points, [CAM], [np.eye(4)]) == 2.0


def test_reference_length_is_the_median_over_all_sightings():
    points = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 3.0], [0.0, 0.0, 5.0]])
    back = Transform(z=-1.0).apply(np.eye(4))  # a second camera one unit behind: depths 2, 4, 6
    assert reference_length(points, [CAM, CAM], [np.eye(4), back]) == 3.5


def test_no_point_seen_is_an_error():
    with pytest.raises(IngestError, match="none of the 1 sparse points is seen by the 1 cameras"):
        reference_length(np.array([[0.0, 0.0, -1.0]]), [CAM], [np.eye(4)])
    with pytest.raises(IngestError, match="no scene bounds"):
        scene_bounds(np.zeros((0, 3)), [CAM], [np.eye(4)])


@settings(deadline=None, max_examples=25)
@given(st.integers(0, 2**32 - 1))
def test_bounds_ignore_stray_points_and_are_padded(seed):
    rng = np.random.default_rng(seed)
    inlier = rng.uniform([-0.5, -0.4, 2.0], [0.5, 0.4, 3.0], size=(2000, 3))
    strays = np.array([[0.0, 0.0, 500.0], [50.0, 0.0, 400.0]])  # seen, but far away
    lo, hi = scene_bounds(np.vstack([inlier, strays]), [CAM], [np.eye(4)])
    size = inlier.max(0) - inlier.min(0)
    assert np.all(hi[2] < 3.5) and np.all(hi[0] < 1.0), f"stray points widened the box: {lo}, {hi}"
    np.testing.assert_allclose(hi - lo, 1.1 * size, rtol=0.1)


def _blob(centre, n=200, seed=0) -> np.ndarray:
    """``n`` points spread ±0.3 around ``centre``."""
    return np.random.default_rng(seed).uniform(-0.3, 0.3, size=(n, 3)) + centre


def test_scene_bounds_cover_what_every_camera_sees():
    right = Transform(x=10.0).apply(np.eye(4))  # sees only the second blob; the first camera only the first
    points = np.vstack([_blob([0.0, 0.0, 2.0]), _blob([10.0, 0.0, 2.0], seed=1)])
    lo, hi = scene_bounds(points, [CAM, CAM], [np.eye(4), right])
    assert lo[0] < 0.0 and hi[0] > 10.0, f"the bounds {lo}, {hi} leave out what one camera sees"


def test_scene_bounds_leave_out_points_no_camera_sees():
    behind = _blob([0.0, 0.0, -50.0], n=100, seed=2)  # a third of the points, all behind the camera
    lo, hi = scene_bounds(np.vstack([_blob([0.0, 0.0, 2.0]), behind]), [CAM], [np.eye(4)])
    assert lo[2] > 1.0, f"the bounds {lo}, {hi} take in points behind the camera"


def test_the_reference_length_is_measured_from_the_training_cameras_only():
    """Held-out views (0 and 2 with ``heldout_every=2``) stand 8 units further back: the unit of the pose
    tolerances must not depend on them."""
    from pytest_n2r.data.ingest import extent
    from pytest_n2r.data.poses import PoseSet, SourceFrame

    far = Transform(z=-8.0).apply(np.eye(4))
    frames = [SourceFrame(f"{k}.png", None, CAM, far if k % 2 == 0 else np.eye(4)) for k in range(4)]
    _, length = extent(PoseSet(frames=frames, points=np.array([[0.0, 0.0, 2.0]])), heldout_every=2)
    assert length == pytest.approx(2.0), f"reference length {length}: the held-out cameras' depth counted"


def _project(c2w: np.ndarray, points: np.ndarray) -> np.ndarray:
    w2c = np.linalg.inv(c2w)
    x = (points @ w2c[:3, :3].T + w2c[:3, 3]) @ CAM.K.T
    return x[:, :2] / x[:, 2:3]


def test_a_pair_keeps_only_points_in_front_that_reproject_with_parallax():
    from pytest_n2r.data.triangulate import _triangulate_pair

    c2w_i, c2w_j = np.eye(4), Transform(x=0.5).apply(np.eye(4))
    points = np.array([[0.0, 0.0, 4.0],       # kept
                       [0.3, 0.1, 3.0],       # matched to a pixel 15 px off in j
                       [0.1, 0.0, -4.0],      # behind both cameras
                       [0.0, 0.2, 1000.0]])   # 0.03° of parallax: its depth is a guess
    ui, uj = _project(c2w_i, points), _project(c2w_j, points)
    uj[1, 1] += 15.0
    _, ok = _triangulate_pair(ui, uj, CAM, CAM, np.linalg.inv(c2w_i), np.linalg.inv(c2w_j), 2.0, 1.5)
    assert ok.tolist() == [True, False, False, False], f"kept {ok.tolist()}"


def test_neighbour_pairs_respect_viewing_direction():
    ahead = [Transform(x=k).matrix() for k in range(4)]  # a row of cameras looking the same way
    behind = Transform(yaw=180, x=0.5).matrix()          # close by, but looking the other way
    pairs = neighbour_pairs(ahead + [behind], neighbours=1)
    assert pairs == [(0, 1), (1, 2), (2, 3)]


def test_triangulate_views_checks_its_inputs():
    img = np.zeros((80, 100, 3), np.uint8)
    with pytest.raises(InvalidArgument, match="one entry per view; got 2, 1, 1"):
        triangulate_views([img, img], [CAM], [np.eye(4)])
    with pytest.raises(InvalidArgument, match="cameras\\[0\\] has lens distortion"):
        triangulate_views([img], [Camera(100, 80, 100.0, 100.0, 49.5, 39.5, (0.1, 0, 0, 0))], [np.eye(4)])
    with pytest.raises(InvalidArgument, match="images\\[0\\] has size 100x80; its camera is 50x40"):
        triangulate_views([img], [CAM.resized(50, 40)], [np.eye(4)])
    assert triangulate_views([img, img], [CAM, CAM], [np.eye(4), Transform(x=1).matrix()]).shape == (0, 3)


def test_atomic_write_leaves_the_old_file_when_writing_fails(tmp_path, monkeypatch):
    target = tmp_path / "poses.json"
    atomic_write_text(target, "old")

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr("os.replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        atomic_write_text(target, "new")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["poses.json"], "temporary file left behind"


def test_atomic_write_gives_a_new_file_the_umask_mode_and_keeps_an_old_files_mode(tmp_path, umask):
    umask(0o027)
    fresh = atomic_write_text(tmp_path / "new.json", "{}")
    mode = stat.S_IMODE(fresh.stat().st_mode)
    assert mode == 0o640, f"a new file got mode {oct(mode)}, expected 0o640 under umask 027"
    kept = tmp_path / "kept.json"
    kept.write_text("old")
    kept.chmod(0o604)
    atomic_write_text(kept, "new")
    mode = stat.S_IMODE(kept.stat().st_mode)
    assert mode == 0o604, f"rewriting a file changed its mode to {oct(mode)}"
    atomic_write_chunks(kept, ["newer"])
    mode = stat.S_IMODE(kept.stat().st_mode)
    assert mode == 0o604, f"rewriting a file in pieces changed its mode to {oct(mode)}"


def test_atomic_write_of_pieces_writes_them_as_they_come_and_keeps_the_old_file_when_they_stop(tmp_path):
    """The HTML report's writer: pieces (a generator) are written as they come, never held whole; pieces that
    raise midway leave the old file as it was and no temporary file, as a failed write does."""
    target = tmp_path / "report.html"
    atomic_write_text(target, "old")
    on_disk = []

    def pieces():
        yield "<html>"
        yield "é" * 10_000  # past any write buffer
        on_disk.extend((p.name, p.stat().st_size) for p in tmp_path.iterdir() if p != target)
        raise RuntimeError("a picture could not be read")

    with pytest.raises(RuntimeError, match="a picture could not be read"):
        atomic_write_chunks(target, pieces())
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.html"], "temporary file left behind"
    assert len(on_disk) == 1 and on_disk[0][0].startswith(".report.html.") and on_disk[0][1] >= 20_000, \
        f"the pieces were not written to a temporary file as they came: {on_disk}"
    assert atomic_write_chunks(target, iter(["<p>", "é", "</p>\n"])) == target
    assert target.read_bytes() == "<p>é</p>\n".encode()


@pytest.mark.parametrize("mask", [0o002, 0o077], ids=["umask 002", "umask 077"])
def test_atomic_write_follows_a_umask_set_after_import(tmp_path, mask, umask):
    """The umask was read once, at import: a conftest's ``os.umask(0o002)`` still gave 0o644 files, where
    :func:`open` gives 0o664 (two masks, so that one differs from the umask at import, whatever it was)."""
    umask(mask)
    mode = stat.S_IMODE(atomic_write_text(tmp_path / "new.json", "{}").stat().st_mode)
    assert mode == 0o666 & ~mask, f"a new file got mode {oct(mode)} under umask {oct(mask)}, " \
        f"expected {oct(0o666 & ~mask)}"


def test_the_umask_is_read_without_setting_it_where_linux_tells_it(tmp_path, monkeypatch, umask):
    """Setting the umask to read it races with other threads creating files: ``/proc/self/status`` is read where
    it has a ``Umask:`` line; elsewhere (no /proc, a kernel before 4.7) the umask is set and restored."""
    try:
        with open("/proc/self/status", "rb") as fh:
            told = any(line.startswith(b"Umask:") for line in fh)
    except OSError:
        told = False
    umask(0o027)
    if told:
        with monkeypatch.context() as m:
            m.setattr(os, "umask", lambda mask: pytest.fail(f"the umask was set to {oct(mask)} to read it"))
            read = atomic.current_umask()
            assert read == 0o027, f"/proc/self/status read as umask {oct(read)}, expected 0o027"
    monkeypatch.setattr(atomic, "_PROC_STATUS", str(tmp_path / "no-such-status"))
    read = atomic.current_umask()
    assert read == 0o027, f"the umask read by setting it was {oct(read)}, expected 0o027"
    assert atomic.current_umask() == 0o027, "reading the umask by setting it did not restore it"


@pytest.mark.parametrize("write", [atomic_write_text, lambda path, text: atomic_write_chunks(path, iter([text]))])
def test_a_file_name_read_under_an_ascii_locale_is_written_as_its_bytes(tmp_path, write):
    """Under LC_ALL=C without UTF-8 mode, `é` in a test's folder reads as two surrogates: the HTML report that
    names it failed with 'surrogates not allowed' and was not written."""
    name = b"caf\xc3\xa9".decode("ascii", "surrogateescape")  # os.fsdecode's result under an ASCII locale
    write(tmp_path / "report.html", f"<p>{name}</p>")
    assert (tmp_path / "report.html").read_bytes() == "<p>café</p>".encode(), "the name's bytes were not kept"
