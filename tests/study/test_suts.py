"""A `module:function` SUT is found in the working folder, as a `module:function` scene is; a malformed one is named."""

from __future__ import annotations

import re
import sys

import numpy as np
import pytest

from pytest_n2r.errors import InvalidArgument, InvalidType
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


@pytest.mark.parametrize("spec", [":foo", "..x:y", ".json:dumps", "json:", "json:a.b", "json.:dumps"])
def test_a_spec_that_is_not_module_colon_callable_is_named(spec):
    """':foo' raised a bare "ValueError: Empty module name", '..x:y' a bare TypeError about a relative import."""
    with pytest.raises(InvalidArgument, match=rf"--sut {re.escape(repr(spec))} is not 'module:attribute': expected an "
                                              r"absolute module name \(package\.module\) before the ':'"):
        resolve_sut(spec, np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(InvalidType, match=r"--sut 3 must be a str: a built-in SUT \(orb, sift, akaze\)"):
        resolve_sut(3, np.zeros((8, 8, 3), np.uint8))
