"""The paper's test of statistical dependence: does a better rendered view (image quality against the real photo)
go with a SUT that agrees more between the photo and the render?

For each SUT metric of the reality-to-field shift (``domain_shift`` rows: the score between the SUT's output on
the real photo and on the τ0 render at its pose) and each image quality metric of that render (the ``tau0``
``realness`` rows: PSNR, SSIM, LPIPS against the same photo), Spearman's rank correlation over the views of every
scene, paired by scene and view. The paper found significant dependence (p < 0.05) for 38 of its 48 combinations.

Convention:
    A view enters a combination when its SUT sample is valid and both values are finite. A view whose render *is*
    its reference (infinite PSNR: an exact scene, which has no field and so no shift) enters none: it would rank
    first on every metric and make a dependence of its own. Higher PSNR and SSIM mean a more faithful render,
    lower LPIPS does, so a dependence shows as a positive ``rho`` for the first two and a negative one for LPIPS.
    Fewer than :data:`MIN_PAIRS` pairs, or a column whose values are all equal, has no rank correlation:
    ``rho`` and ``p`` are NaN and ``significant`` is false (nothing was ranked, not "no dependence").
"""

from __future__ import annotations

import itertools
import math
import numbers
from collections.abc import Sequence

import numpy as np

__all__ = ["ALPHA", "EXACT_UP_TO", "IMAGE_QUALITY", "MIN_PAIRS", "can_be_significant", "rank_correlations"]

#: The image quality metrics of a render against its photo, as RQ1's ``realness`` rows name them.
IMAGE_QUALITY = ("psnr", "ssim", "lpips")
#: The significance level of each test (the paper's).
ALPHA = 0.05
#: Fewer pairs than this have no rank correlation (with two, any two distinct pairs are perfectly correlated).
MIN_PAIRS = 3
#: Up to this many pairs the p-value is exact, over every pairing of the ranks (8! = 40 320); above it, SciPy's
#: t approximation. At 3 pairs a perfect ordering has an exact p of 1/3; the t approximation gives 0.
EXACT_UP_TO = 8


def rank_correlations(realness: Sequence[dict], domain_shift: Sequence[dict]) -> list[dict]:
    """One row per (SUT, SUT metric, image quality metric): ``n`` paired views, Spearman's ``rho``, its two-sided
    ``p`` (exact up to :data:`EXACT_UP_TO` pairs) and whether ``p < ALPHA``.

    >>> realness = [{"scene": "s", "view": f"v{i}", "source": "tau0", "psnr": 20.0 + i, "ssim": 0.5, "lpips": None}
    ...             for i in range(4)]
    >>> shift = [{"scene": "s", "view": f"v{i}", "sut": "orb", "metric": "repeatability", "score": 0.4 + i / 10,
    ...           "valid": True} for i in range(4)]
    >>> [(r["image_quality"], r["n"], r["rho"]) for r in rank_correlations(realness, shift)]
    [('psnr', 4, 1.0), ('ssim', 4, nan), ('lpips', 0, nan)]
    """
    quality = {(r["scene"], r["view"]): r for r in realness if r["source"] == "tau0" and r["psnr"] != math.inf}
    samples: dict[tuple[str, str], list[tuple[dict, float]]] = {}
    for row in domain_shift:
        key = (row["scene"], row["view"])
        if key not in quality:
            continue
        pairs = samples.setdefault((row["sut"], row["metric"]), [])  # reported even with no valid sample
        if row["valid"] and _finite(row["score"]):
            pairs.append((quality[key], float(row["score"])))
    out = []
    for (sut, metric), pairs in sorted(samples.items()):
        for name in IMAGE_QUALITY:
            ranked = [(float(q[name]), score) for q, score in pairs if _finite(q.get(name))]
            rho, p = _spearman([x for x, _ in ranked], [y for _, y in ranked])
            out.append({"sut": sut, "metric": metric, "image_quality": name, "n": len(ranked), "rho": rho, "p": p,
                        "significant": bool(p < ALPHA)})
    return out


def can_be_significant(n: int) -> bool:
    """Whether a rank correlation over ``n`` pairs can reach ``p < ALPHA`` at all: with the exact test the smallest
    p is 2 / n! (both perfect orderings), so 5 pairs are the fewest that can (1/60; 4 give 1/12).

    >>> [n for n in range(3, 10) if can_be_significant(n)][0]
    5
    """
    return n > EXACT_UP_TO or 2 / math.factorial(n) < ALPHA


def _finite(value: object) -> bool:
    return isinstance(value, numbers.Real) and math.isfinite(value)


def _spearman(x: Sequence[float], y: Sequence[float]) -> tuple[float, float]:
    """Spearman's rho and its two-sided p-value; NaN for both where there is nothing to rank (the module's
    Convention). Ties take their mean rank."""
    if len(x) < MIN_PAIRS or len(set(x)) < 2 or len(set(y)) < 2:
        return math.nan, math.nan
    from scipy.stats import rankdata, spearmanr

    if len(x) > EXACT_UP_TO:
        result = spearmanr(x, y)
        return float(result.statistic), float(result.pvalue)
    rx, ry = rankdata(x) - (len(x) + 1) / 2, rankdata(y) - (len(y) + 1) / 2  # centred: the mean rank is (n + 1) / 2
    scale = float(np.sqrt((rx @ rx) * (ry @ ry)))
    observed = float(rx @ ry)
    null = np.array(list(itertools.permutations(ry))) @ rx  # every pairing of the ranks, equally likely under H0
    p = float(np.mean(np.abs(null) >= abs(observed) - 1e-9 * scale))
    return observed / scale, p
