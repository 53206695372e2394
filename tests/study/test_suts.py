"""A `module:function` SUT is found in the working folder, as a `module:function` scene is."""

from __future__ import annotations

import sys

import numpy as np

from pytest_n2r.study import resolve_sut

DETECTOR = """import numpy as np
def detect(img):
    return np.array([[1.0, 2.0], [3.0, 4.0]], dtype=np.float32)
"""


def test_a_sut_module_in_the_working_folder_is_imported(tmp_path, monkeypatch):
    """`n2r study --sut mysut:detect` beside mysut.py failed: No module named 'mysut'."""
    (tmp_path / "n2r_test_cwd_sut.py").write_text(DETECTOR)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])  # as the n2r script
    monkeypatch.delitem(sys.modules, "n2r_test_cwd_sut", raising=False)
    sut = resolve_sut("n2r_test_cwd_sut:detect", np.zeros((9, 16, 3), np.uint8))
    assert (sut.name, sut.kind) == ("detect", "detector")
    assert sys.path[-1] == str(tmp_path), "the working folder goes last, not shadowing installed packages"
    monkeypatch.delitem(sys.modules, "n2r_test_cwd_sut")
