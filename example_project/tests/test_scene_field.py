"""The same detectors on *fitted* scenes: the demo scenes' fitted twins, scene fields like the one ``n2r fit``
makes of your own capture.

``demo:wall-field`` and ``demo:object-field`` are radiance fields fitted to photos of the exact demo scenes
(they ship with pytest-n2r; nothing is fitted or downloaded). A relation on them compares the detector on
two *renders of the field*, as every relation on a user's own capture does. pytest-n2r prints beside each
result the **field floor** (the detector on the exact image against the field's render at the same held-out
pose: what the field alone does to the metric) and, because the twins' truth is known, the same examples
replayed on exact renders (how much of the deviation is the field's).

``eps`` as in test_detectors.py: the worst deviation of the shipped configuration over the 10 derandomized
examples per scene (320×180), rounded up to keep at least 0.08 above it, and kept above the field floor.
Measured in two cold runs whose draws differed (pytest-n2r's strategies changed between them): worst
deviation; field floor, mean over the 6 held-out views; mean deviation of the same examples on exact renders
vs on the field:

- ORB repeatability τ1: wall-field 0.436 / 0.441 (floor 0.437; 0.296 exact vs 0.307 field), object-field
  0.448 / 0.466 (floor 0.472; 0.312 vs 0.320): eps 0.55, below test_detectors.py's 0.6 on the exact scenes;
- AKAZE repeatability τ1: wall-field 0.175 / 0.156 (floor 0.128; 0.026 vs 0.071), object-field 0.192 /
  0.154 (floor 0.210; 0.076 vs 0.065): eps 0.3.

On 4 December, with today's draws, the worst deviations were ORB 0.449 / 0.517 and AKAZE 0.200 / 0.154 (wall-field
/ object-field); with the render defaults of that evening (``t_stop=0.04``, ``min_weight=2e-2``) ORB 0.451 / 0.476 and
AKAZE 0.200 / 0.196, the floors ORB 0.437 / 0.495 and AKAZE 0.131 / 0.212 (0.438 / 0.474 and 0.132 / 0.204 before).
ORB on object-field is now 0.03–0.07 below its eps, not 0.08: eps stays, as no measurement says the relation, not
the draws, moved (docs/performance-log.md, "Rendering").

Since repeatability counts the largest one-to-one matching, not mutual nearest neighbours only (``result_version``
2, as in test_detectors.py), the same examples replayed with both matchings: ORB's mean deviation 0.310 -> 0.122
(wall-field) and 0.326 -> 0.157 (object-field), worst 0.451 -> 0.185 and 0.476 -> 0.273; AKAZE's 0.069 -> 0.028 and
0.065 -> 0.056. The floors fell with them: ORB 0.160 / 0.304 (max 0.258 / 0.661), AKAZE 0.109 / 0.181 (wall-field /
object-field): most of what looked like the fields' effect on ORB was the matching. On the new draws the worst
deviations are ORB 0.171 / 0.302 and AKAZE 0.059 / 0.250; the field adds −0.011 / −0.023 (ORB) and −0.015 /
−0.002 (AKAZE) to the mean deviation of the same poses on exact renders. ORB's eps is derived again as in
test_detectors.py, from those 10 draws and 100 more (eps 0.99): worst 0.225 / 0.410, so 0.55 -> 0.5, above its
floors. AKAZE's 0.3 stays (0.05 above object-field's new worst draw; the matching moved it by at most 0.041 on
the same examples).

On 6 December pytest-n2r's search stopped drawing the identity and counting repeated examples: on those draws the
worst deviations are ORB 0.155 / 0.333 and AKAZE 0.073 / 0.127 (wall-field / object-field; the wall's ORB relation
alone: the field adds −0.023 to the mean deviation of the same poses on exact renders); both eps stay, above the
rule and the floors.

Two renders of one field share most of its errors: on the same examples the field adds −0.01 to +0.045 to
the mean deviation, though its floor (one render against the truth) is 0.13–0.47. Not asserted here,
measured the same way: EfficientNet-Lite0's cosine similarity under τ1 on object-field (worst 0.345) has a
floor of 0.60 (max 0.94): the fitted van's blur moves the network's class probabilities more than a small
motion does, so a classifier relation on a fitted scene would test the field, not the network
(docs/scene-field.md).
"""

from __future__ import annotations

import pytest
from perception.detectors import detector

from pytest_n2r import metamorphic

from .test_detectors import REPEATABILITY

#: The fitted twins of the demo scenes (pinned: they run whatever ``n2r_scenes`` / ``--n2r-scene`` name).
FITTED = ("demo:wall-field", "demo:object-field")
#: Examples per relation: half the suite's 20. Fitted renders are slower than exact ones: with 10 examples the
#: four relations, the twins' loading and their floors took about 24 s of a cold 173 s run of the whole suite.
EXAMPLES = 10

pytestmark = [pytest.mark.field, pytest.mark.detectors, pytest.mark.n2r_scene(*FITTED)]


@metamorphic(REPEATABILITY, eps=0.5, transform="tau1", examples=EXAMPLES)
def test_orb_repeatability_tau1(n2r_scene, orb):
    return orb


@metamorphic(REPEATABILITY, eps=0.3, transform="tau1", examples=EXAMPLES)
def test_akaze_repeatability_tau1(n2r_scene):
    return detector("akaze")
