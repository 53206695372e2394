"""A relief's hits along the ray caster's rows of rays (numba): each pixel row's pixel-centre rays first, their
roots searched from the roots of the rows above; then its rows of sub-pixel rays, each root taken from its
pixel centre's model of the relief where that is accurate (:func:`.relief_kernel.relief_hits`).

A sub-pixel ray's hit lies within a pixel of its pixel centre's. The relief there is its second-order Taylor
expansion about the centre's hit, whose terms the centre's last evaluation gives (the waves' sines and cosines
give the second derivatives as well): the sub-ray's root and gradient follow from it without evaluating the
waves again, as accurately as a search ends (the bound of the expansion's error, from the waves' third
derivatives, is checked per ray; rays beyond it search as before).

Convention
----------
- A relief's buffer (``relief``, one per relief of the scene, ``_RELIEF_ROWS`` rows of the widest row of rays)
  holds the batch's hits (:data:`.relief_kernel.HIT_ROWS` rows from :data:`_HITS`), the roots of the last three
  rows of pixel-centre rays (the newest last), and the models at the last row of pixel-centre hits, each
  repeated for the sub-pixel rays of its pixel (:data:`.relief_kernel.MODEL_ROWS` rows from :data:`_MODEL`).
- The history restarts at each band of image rows (``rows``: the rows of centres above in this band), so
  that images do not depend on the thread count (see :mod:`.raycast`).
"""

from __future__ import annotations

import math

from numba import njit

from .relief_kernel import HIT_ROWS, MODEL_ROWS, relief_hits, set_models

__all__ = ["RELIEF_ROWS", "relief_row"]

_HITS = 0
_HISTORY = _HITS + HIT_ROWS
_MODEL = _HISTORY + 3
#: Rows of a relief's buffer (see the module *Convention*).
RELIEF_ROWS = _MODEL + MODEL_ROWS


@njit(cache=True, inline="always", error_model="numpy")
def _extrapolate(history, rows, j):
    """A guess of a relief root at ray ``j`` of the next row of rays from the relief's roots at ray ``j`` of the
    last ``rows`` rows (``history[0:3]``, the newest last; fewer than three at a band's start): the quadratic
    extrapolation where all three hit it, else the linear, else the last root; NaN where the last row missed."""
    if rows < 1 or not math.isfinite(history[2, j]):
        return math.nan
    if rows >= 2 and math.isfinite(history[1, j]):
        if rows >= 3 and math.isfinite(history[0, j]):
            return 3.0 * (history[2, j] - history[1, j]) + history[0, j]
        return 2.0 * history[2, j] - history[1, j]
    return history[2, j]


@njit(cache=True, inline="always", error_model="numpy")
def relief_row(k, prims, waves, lanes, ox, oy, oz, ds, guesses, count, us, v, rect, state, sums, spare, relief, n,
               rows, centre):
    """Relief ``k``'s hits along one row of ``count`` rays (``relief[_HITS:_HITS + 4]``, see
    :func:`.relief_kernel.relief_hits`): pixel-centre rays (``centre``) searched from the roots of the ``rows``
    rows of centres above (:func:`_extrapolate`; then their roots join that history), their hits then the
    models of their pixels' sub-pixel rays; a row of sub-pixel rays (``n`` to a pixel along the row) from those
    models, or searched from the models' roots."""
    history = relief[_HISTORY:_HISTORY + 3]
    if centre:
        for j in range(count):
            guesses[j] = _extrapolate(history, rows, j)
    hits, model = relief[_HITS:_HITS + HIT_ROWS], relief[_MODEL:_MODEL + MODEL_ROWS]
    relief_hits(prims, k, waves, lanes, ox, oy, oz, ds, guesses, count, us, v, rect, state, sums, spare, hits, model,
                not centre)
    if centre:
        set_models(hits, ox, oz, ds, count, n, model)
        for j in range(count):
            history[0, j], history[1, j], history[2, j] = history[1, j], history[2, j], relief[_HITS, j]
