"""The example's EfficientNet-Lite0 pads like TensorFlow's ``"same"``: its weights were trained that way, so a
convolution padded otherwise would shift every feature map by a pixel and the example's classifier relations would
measure a network it is not.
"""

from __future__ import annotations

import math
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ..conftest import REPO_ROOT

torch = pytest.importorskip("torch")
F = torch.nn.functional


@pytest.fixture(scope="module")
def same_conv():
    """``perception.networks._SameConv``, imported from the example project without installing it."""
    sys.path.insert(0, str(REPO_ROOT / "example_project"))
    try:
        from perception.networks import _SameConv
    finally:
        sys.path.remove(str(REPO_ROOT / "example_project"))
    return _SameConv


def _tensorflow_same(x, conv):
    """TensorFlow's ``"same"``: output ``ceil(size / stride)``, the total padding split with the odd pixel after."""
    pads = []
    for size, k, s in zip(x.shape[-2:], conv.kernel_size, conv.stride):
        total = max((math.ceil(size / s) - 1) * s + k - size, 0)
        pads.append((total // 2, total - total // 2))
    (top, bottom), (left, right) = pads
    return F.conv2d(F.pad(x, (left, right, top, bottom)), conv.weight, conv.bias, conv.stride, 0, 1, conv.groups)


@settings(max_examples=60, deadline=None)
@given(height=st.integers(1, 19), width=st.integers(1, 19), kernel=st.sampled_from([1, 3, 5]),
       stride=st.sampled_from([1, 2]), depthwise=st.booleans(), seed=st.integers(0, 2**16))
def test_same_conv_pads_as_tensorflow(same_conv, height, width, kernel, stride, depthwise, seed):
    torch.manual_seed(seed)
    channels = 4
    conv = same_conv(channels, channels, kernel, stride, groups=channels if depthwise else 1, bias=False)
    x = torch.randn(1, channels, height, width)
    with torch.inference_mode():
        got, want = conv(x), _tensorflow_same(x, conv)
    assert got.shape == want.shape == (1, channels, math.ceil(height / stride), math.ceil(width / stride)), \
        f"{height}×{width}, kernel {kernel}, stride {stride}: {tuple(got.shape)}, TensorFlow's {tuple(want.shape)}"
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-6,
                               msg=lambda m: f"{height}×{width}, kernel {kernel}, stride {stride}: {m}")
