"""Compiled blend masks in numba's on-disk cache: a second process loads them, a changed mask is compiled again
under another name, and a first render compiles them and the ray caster's row cast after the kernel (another
process may have meanwhile: the row cast waits for it)."""

from __future__ import annotations

import importlib.util
import inspect
import json
import os
import subprocess
import sys
import threading
import time
import types
from pathlib import Path

import numpy as np

from pytest_n2r.demo.mask_kernel import compile_mask, mask_fingerprint

#: Compiles the demo scenes' masks and prints, per mask, whether numba loaded it from its cache.
_CHILD = """
import json
from pytest_n2r.demo.mask_kernel import compile_mask
from pytest_n2r.demo.scenes import _growth_mask, _road_mask
print(json.dumps({m.__name__: sum(compile_mask(m).stats.cache_hits.values()) for m in (_growth_mask, _road_mask)}))
"""


def _cache_hits(numba_cache: Path) -> dict[str, int]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(numba_cache)}
    done = subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


def test_a_second_process_loads_the_demo_masks_from_numbas_cache(tmp_path):
    assert _cache_hits(tmp_path) == {"_growth_mask": 0, "_road_mask": 0}, "a fresh cache held the masks already"
    assert _cache_hits(tmp_path) == {"_growth_mask": 1, "_road_mask": 1}, "the second process compiled a mask again"


_MASK_SOURCE = """
import numpy as np

SHARPNESS = {sharpness}

def edge(x):
    return np.minimum(np.maximum(SHARPNESS * x, 0.0), 1.0)

def mask(a, b):
    return edge(np.sin(a) * np.cos(b) + {offset})
"""


def _mask_module(folder: Path, name: str, sharpness: float = 2.0, offset: float = 0.0):
    path = folder / f"{name}.py"
    path.write_text(_MASK_SOURCE.format(sharpness=sharpness, offset=offset))
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_masks_name_follows_its_code_its_helpers_and_their_globals(tmp_path):
    base = _mask_module(tmp_path, "base")
    assert mask_fingerprint(base.mask) == mask_fingerprint(_mask_module(tmp_path, "base").mask), \
        "the same file gave another name"
    names = {mask_fingerprint(base.mask)}
    for label, changed in (("the mask's code", _mask_module(tmp_path, "base", offset=0.5).mask),
                           ("a helper's global", _mask_module(tmp_path, "base", sharpness=3.0).mask)):
        assert mask_fingerprint(changed) not in names, f"a change of {label} kept the compiled mask's name"
        names.add(mask_fingerprint(changed))
    module = _mask_module(tmp_path, "patched")
    before = mask_fingerprint(module.mask)
    module.SHARPNESS = 5.0  # a global changed at run time: numba freezes the value it compiles with
    assert mask_fingerprint(module.mask) != before, "a changed global kept the compiled mask's name"


def test_masks_without_a_stable_name_compile_in_every_process_and_still_work():
    table = np.linspace(0, 1, 4)
    code = compile("def typed(a, b):\n    return 0.5 + 0.5 * np.sin(a) * np.cos(b)\n", "<prompt>", "exec")
    typed = types.FunctionType(code.co_consts[0], {"np": np})  # as if typed into a prompt: no source file

    def closure(a, b):
        return table[0] + a * b

    assert mask_fingerprint(typed) is None, "a mask without a source file got a name on disk"
    assert mask_fingerprint(closure) is None, "a mask closing over an array got a name on disk"
    a, b = np.linspace(-3, 3, 7), np.linspace(2, -2, 7)
    for fn in (typed, closure):
        out = np.empty(7)
        compile_mask(fn)(a, b, out, 7)
        np.testing.assert_allclose(out, fn(a, b), rtol=0, atol=1e-15, err_msg=f"{fn.__name__} compiled wrong")


def test_a_first_render_runs_the_kernel_before_it_compiles_the_masks_and_the_row_cast(monkeypatch):
    """So that another process can compile them meanwhile (the kernel helper: compile_apart)."""
    from pytest_n2r.demo import raycast, row_cast
    from pytest_n2r.demo.scenes import wall_scene

    events: list[str] = []
    kernel, compile_one, cast_row = raycast._render_kernel, raycast.compile_mask, row_cast.cast_row_kernel
    parameters = list(inspect.signature(kernel.py_func).parameters)
    masks_at, cast_at = parameters.index("masks"), parameters.index("cast_row")

    def kernel_call(*args):
        placeholders = args[masks_at][0] is raycast.no_mask, args[cast_at][0] is row_cast.no_cast_row()
        events.append({(True, True): "kernel, placeholders", (False, False): "kernel"}[placeholders])
        return kernel(*args)

    def mask_call(fn):
        events.append(f"mask {fn.__name__}")
        return compile_one(fn)

    def cast_row_call():
        events.append("row cast")
        return cast_row()

    monkeypatch.setattr(raycast, "_render_kernel", kernel_call)
    monkeypatch.setattr(raycast, "compile_mask", mask_call)
    monkeypatch.setattr(raycast, "cast_row_kernel", cast_row_call)
    monkeypatch.setattr(row_cast, "cast_row_kernel", cast_row_call)
    monkeypatch.setattr(raycast.numba, "get_num_threads", lambda: 1)
    scene = wall_scene()
    view = scene.views[0]
    first = scene.render(view.c2w, view.camera.resized(16, 9), ("rgb",))
    scene.render(view.c2w, view.camera.resized(16, 9), ("rgb",))
    expected = ["kernel, placeholders", "mask _growth_mask", "row cast", "kernel", "row cast", "kernel"]
    assert events == expected, events
    again = wall_scene()
    assert again.compile_apart(), "compile_apart said the scene has nothing to compile apart"
    assert events[-2:] == ["row cast", "mask _growth_mask"], f"compile_apart did not compile both: {events}"
    np.testing.assert_array_equal(again.render(view.c2w, view.camera.resized(16, 9), ("rgb",)).rgb, first.rgb)


def test_the_row_cast_waits_for_another_process_compiling_it(tmp_path):
    """A first render that reaches the row cast while the kernel helper compiles it waits for its lock."""
    from pytest_n2r.demo import row_cast
    from pytest_n2r.scene import first_render as fr

    row_cast.cast_row_kernel.cache_clear()  # this process's compiled copy: the next call takes the lock again
    ready, release = threading.Event(), threading.Event()

    def hold():
        with fr.claim_kind(tmp_path, f"piece-{row_cast.CAST_ROW_PIECE}", wait=False) as held:
            assert held
            ready.set()
            release.wait(5)

    holder = threading.Thread(target=hold)
    holder.start()
    ready.wait()
    threading.Timer(0.5, release.set).start()
    start = time.perf_counter()
    with fr.kernel_locks(tmp_path):
        compiled = row_cast.cast_row_kernel()
    waited = time.perf_counter() - start
    holder.join()
    assert waited >= 0.4, f"the row cast went ahead after {waited:.2f} s while another process held its lock"
    assert compiled.signatures, "the row cast was not compiled or loaded"
