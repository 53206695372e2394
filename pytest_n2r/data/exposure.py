"""How much exposure and white balance vary from photo to photo in a capture, measured from the photos alone.

A phone sets exposure and white balance anew for every photo, so one surface is stored brighter or bluer in
one photo than in the next. The fit can model that (a colour gain per photo, :mod:`pytest_n2r.fit.appearance`);
this module says how much a capture has of it, before any field exists.

Method
------
Neighbouring photos are matched and each match kept only where it triangulates consistently with the known
poses (:func:`~.triangulate.matched_pairs`, any parallax). At every kept match both photos' colours are read
from the photo smoothed by a Gaussian of ``patch_px`` pixels (a patch, not the feature's corner pixel), and
where no channel of either is near black or near clipping, the log ratio is taken per channel. A pair's ratio
is the median over its matches (a highlight that moves with the view, or a wrong match, is an outlier), and
the photos' log gains solve ``gain_i − gain_j = ratio_ij`` over all pairs in the least-squares sense, with
their mean fixed at 0. Photos outside the largest group linked by pairs are not measured.

Convention
----------
Gains are per channel (R, G, B) of the stored 8-bit values (sRGB-encoded), the quantity the fit's appearance
correction multiplies: a photo with log gain ``g`` stores ``exp(g)`` times the capture's average colour. Two
numbers summarize a capture, both natural-log (0.05 ≈ 5 %): ``spread``, the root mean square over channels of
the standard deviation over photos of the gains (the whole capture: a slow drift along the path counts), and
``jump``, the median over neighbouring pairs of their ratio's root mean square over channels (what changes
from one photo to the next). Images are ``H x W x 3`` uint8 RGB, ideal pinhole; poses camera-to-world, OpenCV
axes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgument
from .capture import CapturedView
from .triangulate import matched_pairs

__all__ = ["ExposureSpread", "measure_exposure", "log_gains_from_ratios"]

#: Stored values (0-255) a colour read must lie strictly between in every channel of both photos: below,
#: sensor noise and JPEG dominate the ratio; above, the channel may be clipped.
DARKEST, BRIGHTEST = 16.0, 236.0
#: Reads a pair needs for its ratio to count.
MIN_READS = 20


@dataclass(frozen=True, eq=False)
class ExposureSpread:
    """Each photo's colour gain against the capture's average, and how much neighbouring photos differ
    (:mod:`module docstring <pytest_n2r.data.exposure>`).

    ``log_gains`` is ``(N, 3)`` natural-log gains per photo and channel, NaN for a photo that could not be
    measured; ``pairs`` lists the neighbouring photos ``(i, j)`` compared and ``ratios`` ``(len(pairs), 3)`` the
    median log ratio of photo i's colours to photo j's at their matches; ``reads`` counts the colour reads.
    """

    names: list[str]
    log_gains: np.ndarray
    pairs: list[tuple[int, int]]
    ratios: np.ndarray
    reads: int

    @property
    def measured(self) -> np.ndarray:
        """``(N,)`` mask of the photos whose gains were measured."""
        return np.all(np.isfinite(self.log_gains), axis=1)

    @property
    def spread(self) -> float | None:
        """How much the measured photos' gains differ over the whole capture (natural log, RMS over channels of
        the std over photos); ``None`` when fewer than two photos were measured: nothing to compare is no
        evidence of a steady camera."""
        g = self.log_gains[self.measured]
        if len(g) < 2:
            return None
        return float(np.sqrt(np.mean(np.var(g, axis=0))))

    @property
    def jump(self) -> float | None:
        """How much neighbouring photos differ: the median over compared pairs of their log ratio's RMS over
        channels (a drift along the capture path moves it little; a new exposure at every photo does);
        ``None`` when no pair was compared."""
        if not len(self.pairs):
            return None
        return float(np.median(np.sqrt(np.mean(np.square(self.ratios), axis=1))))

    @property
    def residual(self) -> float | None:
        """Root mean square of what the gains leave of the pairs' ratios: small when one gain per photo
        explains the capture, large when colours change with the surface and the viewing direction instead;
        ``None`` when the pairs between measured photos do not outnumber what the gains need (a chain or a tree
        of pairs is fitted exactly: nothing is left to compare)."""
        left = [r - (self.log_gains[i] - self.log_gains[j]) for (i, j), r in zip(self.pairs, self.ratios)
                if self.measured[i] and self.measured[j]]
        if not left or len(left) <= int(self.measured.sum()) - 1:
            return None
        return float(np.sqrt(np.mean(np.square(left))))

    def summary(self) -> dict:
        """A JSON-ready record: spread, jump, residual, counts, and each measured photo's gains (R, G, B)."""

        def rounded(x: float | None) -> float | None:
            return None if x is None else round(x, 4)

        return {
            "spread": rounded(self.spread), "jump": rounded(self.jump), "residual": rounded(self.residual),
            "photos": int(self.measured.sum()), "of": len(self.names), "pairs": len(self.pairs), "reads": self.reads,
            "gains": {n: [round(float(x), 4) for x in np.exp(g)]
                      for n, g, ok in zip(self.names, self.log_gains, self.measured) if ok},
        }


def log_gains_from_ratios(n: int, pairs: Sequence[tuple[int, int]], ratios: np.ndarray) -> np.ndarray:
    """``(n, C)`` log gains with ``gain_i − gain_j ≈ ratios[k]`` for ``pairs[k] = (i, j)``, least squares,
    their mean 0 over the photos in the largest group linked by pairs; NaN for every other photo.

    >>> log_gains_from_ratios(4, [(0, 1), (1, 2)], np.array([[0.1], [0.2]])).round(4).ravel().tolist()
    [0.1333, 0.0333, -0.1667, nan]
    """
    ratios = np.asarray(ratios, dtype=np.float64)
    if ratios.ndim != 2 or len(ratios) != len(pairs):
        raise InvalidArgument(f"ratios has shape {ratios.shape}; expected ({len(pairs)}, channels): a row per pair")
    for i, j in pairs:
        if not (0 <= i < n and 0 <= j < n and i != j):
            raise InvalidArgument(f"pairs holds ({i}, {j}); expected two different photos in 0..{n - 1}")
    out = np.full((n, ratios.shape[1]), np.nan)
    group = _largest_group(n, pairs)
    if len(group) < 2:
        return out
    index = {photo: k for k, photo in enumerate(group)}
    kept = [k for k, (i, j) in enumerate(pairs) if i in index and j in index]
    a = np.zeros((len(kept) + 1, len(group)))
    for row, k in enumerate(kept):
        i, j = pairs[k]
        a[row, index[i]], a[row, index[j]] = 1.0, -1.0
    a[-1] = 1.0  # the mean is 0: one more equation fixes the common offset the pairs cannot see
    b = np.vstack([ratios[kept], np.zeros((1, ratios.shape[1]))])
    out[group] = np.linalg.lstsq(a, b, rcond=None)[0]
    return out


def measure_exposure(views: Sequence[CapturedView], *, patch_px: float = 3.0, neighbours: int = 4,
                     max_side: int = 640) -> ExposureSpread:
    """Each photo's colour gain against the capture's average, from colours at matches between each photo and its
    ``neighbours`` nearest (see the module docstring; the jump depends on how far apart neighbours are: the fox
    jumps 0.019 with 4 and 0.029 with 6). Photos are shrunk to at most ``max_side`` pixels on their longer side
    first (``patch_px`` is in pixels of the shrunk photo). Every view needs its image loaded."""
    import cv2

    from .images import resize_image

    if not patch_px > 0:
        raise InvalidArgument(f"patch_px={patch_px!r}: expected pixels > 0")
    if not (isinstance(neighbours, int) and neighbours >= 1):
        raise InvalidArgument(f"neighbours={neighbours!r}: expected an integer >= 1")
    if not (isinstance(max_side, int) and max_side >= 64):
        raise InvalidArgument(f"max_side={max_side!r}: expected an integer >= 64 (pixels; SIFT needs the detail)")
    missing = [v.name for v in views if v.image is None]
    if missing:
        raise InvalidArgument(f"measure_exposure needs every view's image; not loaded: {', '.join(missing[:5])}"
                              + (f" and {len(missing) - 5} more" if len(missing) > 5 else ""))
    cameras = [v.camera.fit_within(max_side) for v in views]
    images: list[np.ndarray] = []
    for v, c in zip(views, cameras):
        assert v.image is not None, "checked above: every image is loaded"
        images.append(v.image if c is v.camera else resize_image(v.image, c.width, c.height))
    found = matched_pairs(images, cameras, [v.c2w for v in views], neighbours=neighbours, min_angle_deg=0.0)
    read: list[list[np.ndarray]] = [[np.empty(0), np.empty(0)] for _ in found]  # pair -> colours in i, in j
    by_photo: dict[int, list[tuple[int, int, np.ndarray]]] = {}
    for p, m in enumerate(found):
        by_photo.setdefault(m.i, []).append((p, 0, m.ui))
        by_photo.setdefault(m.j, []).append((p, 1, m.uj))
    for k, wanted in by_photo.items():  # one smoothed photo at a time: memory does not grow with the capture
        smooth = cv2.GaussianBlur(images[k].astype(np.float32), (0, 0), patch_px)
        for p, side, uv in wanted:
            read[p][side] = _read(smooth, uv)
    pairs, ratios, reads = [], [], 0
    for m, (ci, cj) in zip(found, read):
        ok = np.all((ci > DARKEST) & (ci < BRIGHTEST) & (cj > DARKEST) & (cj < BRIGHTEST), axis=1)
        if ok.sum() < MIN_READS:
            continue
        pairs.append((m.i, m.j))
        ratios.append(np.median(np.log(ci[ok]) - np.log(cj[ok]), axis=0))
        reads += int(ok.sum())
    ratios_arr = np.array(ratios).reshape(-1, 3)
    gains = log_gains_from_ratios(len(views), pairs, ratios_arr)
    return ExposureSpread([v.name for v in views], gains, pairs, ratios_arr, reads)


def _read(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``(M, 3)`` colours of ``image`` at the pixels nearest ``uv`` (x right, y down, centres at integers)."""
    h, w = image.shape[:2]
    x = np.clip(np.rint(uv[:, 0]).astype(np.int64), 0, w - 1)
    y = np.clip(np.rint(uv[:, 1]).astype(np.int64), 0, h - 1)
    return image[y, x].astype(np.float64)


def _largest_group(n: int, pairs: Sequence[tuple[int, int]]) -> list[int]:
    """The photos of the largest group linked by ``pairs`` (ties: the one with the lowest photo), sorted;
    empty when there is no pair."""
    parent = list(range(n))

    def root(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for i, j in pairs:
        parent[root(i)] = root(j)
    linked = {k for pair in pairs for k in pair}
    groups: dict[int, list[int]] = {}
    for k in sorted(linked):
        groups.setdefault(root(k), []).append(k)
    return max(groups.values(), key=len, default=[])
