"""A fixed temporary folder of this user's that no other user can have planted (pytest_n2r/private_folder.py)."""

from __future__ import annotations

import os
import stat

import pytest

from pytest_n2r.private_folder import private_temp_folder


@pytest.fixture
def temp(monkeypatch, tmp_path):
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    return tmp_path


def test_the_folder_is_made_for_this_user_alone_and_found_again(temp):
    folder = private_temp_folder("n2r-test")
    assert folder.parent == temp and folder.name.startswith("n2r-test-"), folder
    assert stat.S_IMODE(folder.lstat().st_mode) == 0o700, f"made with mode {oct(folder.lstat().st_mode)}"
    assert private_temp_folder("n2r-test") == folder, "a second call did not find the same folder"


@pytest.mark.skipif(not hasattr(os, "getuid"), reason="owners and modes of POSIX folders")
@pytest.mark.parametrize("planted", ["open to all", "writable by the group", "a link", "a file", "another user's"])
def test_a_folder_another_user_could_have_planted_is_not_used(temp, planted):
    """numba unpickles the kernels it finds in its cache folder: a fixed name in /tmp that another local user made
    first would run that user's code as this one."""
    fixed = temp / f"n2r-test-{os.getuid()}"
    if planted in ("open to all", "writable by the group"):
        fixed.mkdir()
        fixed.chmod(0o777 if planted == "open to all" else 0o770)
    elif planted == "a link":
        (temp / "elsewhere").mkdir(mode=0o700)
        fixed.symlink_to(temp / "elsewhere")
    elif planted == "a file":
        fixed.write_text("")
    else:
        if os.geteuid() != 0:
            pytest.skip("making a folder another user owns needs root")
        fixed.mkdir(mode=0o700)
        os.chown(fixed, 65534, 65534)
    folder = private_temp_folder("n2r-test")
    assert folder != fixed and folder.is_dir(), f"the planted {fixed} ({planted}) was used"
    assert stat.S_IMODE(folder.lstat().st_mode) == 0o700 and folder.lstat().st_uid == os.getuid()


@pytest.mark.skipif(not hasattr(os, "getuid"), reason="owners and modes of POSIX folders")
def test_this_users_folder_that_others_may_read_is_kept_and_closed(temp):
    """The folder an earlier version made (0o755: numba's makedirs, the demo cache's mkdir) was refused for good,
    so every process compiled its kernels and fitted the demo scenes again, in a new temporary folder each time."""
    fixed = temp / f"n2r-test-{os.getuid()}"
    fixed.mkdir()
    fixed.chmod(0o755)
    assert private_temp_folder("n2r-test") == fixed, "this user's folder, written by no other, was not used"
    assert stat.S_IMODE(fixed.lstat().st_mode) == 0o700, "the folder was left open to other users' reading"
