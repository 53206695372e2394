"""The device a fit or a scene uses: ``"auto"`` picks CUDA where there is one, and a named device must exist."""

from __future__ import annotations

import pytest
import torch

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.device import resolve_device


@pytest.fixture
def two_gpus(monkeypatch):
    """A machine with two CUDA devices, as torch sees it."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)


@pytest.mark.parametrize("device", ["cuda:2", "cuda:3", torch.device("cuda", 7)])
def test_a_gpu_index_the_machine_lacks_is_refused_naming_the_device(two_gpus, device):
    with pytest.raises(InvalidArgument) as info:
        resolve_device(device)
    message = str(info.value)
    assert message.startswith(f"device={device!r}:") and "2 CUDA device(s), 'cuda:0' to 'cuda:1'" in message, (
        f"{device!r} on a machine with two GPUs: the error does not name the device and the GPUs there are: "
        f"{message}")


@pytest.mark.parametrize("device, expected", [("cuda", "cuda"), ("cuda:1", "cuda:1"), ("auto", "cuda"),
                                              ("cpu", "cpu")])
def test_a_device_the_machine_has_is_resolved(two_gpus, device, expected):
    assert resolve_device(device) == torch.device(expected), f"device={device!r} did not resolve to {expected}"


def test_cuda_where_there_is_none_is_refused(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(InvalidArgument, match=r"device='cuda:0': CUDA is not available on this machine"):
        resolve_device("cuda:0")
    assert resolve_device("auto") == torch.device("cpu"), "'auto' without CUDA did not resolve to the CPU"


@pytest.mark.parametrize("device", ["cuda:01", "cuda:00", "gpu", "cpu:1", "CUDA", " cpu"])
def test_a_name_torch_would_not_read_is_refused_before_torch_sees_it(device):
    """`--n2r-device cuda:01` passed the start and then failed every test's setup in torch.device."""
    from pytest_n2r.field.device import check_device

    with pytest.raises(InvalidArgument, match=r"expected 'auto', 'cpu' or 'cuda\[:N\]'"):
        check_device(device)


def test_a_cpu_device_with_its_index_is_the_cpu():
    assert resolve_device(torch.device("cpu", 0)) == resolve_device("cpu:0") == torch.device("cpu:0")
