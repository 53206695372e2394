"""Interest-point detectors under the paper's pose transforms τ1–τ6 (AUV wall inspection).

Each test returns the detector; pytest-n2r renders a source view and its follow-up under τ, runs the
detector on both and checks the metric. ``eps`` is the largest deviation from the ideal (1) we accept:
the worst deviation of the shipped configuration over 20 derandomized examples per scene (demo scenes
``wall`` and ``object``, 320×180) rounded up with a margin of about 0.1. The large motions τ3/τ4 on the
object scene turn much of the view to sky or grass, hence eps up to 0.9 there; regressions within eps are
the baseline gate's job (README.md). One early cold run, made while another run of the suite shared its
cache and example database, drew other examples on the object scene than later ones (spread under τ6:
worst 0.534 there, 0.57 later); the two clean cold runs since gave identical results. eps keeps at least
0.08 above the worst deviation seen in any of them.

Re-measured when pytest-n2r's derandomized search stopped drawing Hypothesis's constants from the source of
the loaded modules (the drawn examples changed; issue 15): on the new draws four relations broke the 0.08
rule, and their eps went up to keep it, not to hide a regression (that is the gate's job, test_gate.py):
ORB repeatability τ4 worst 0.825 (object; eps 0.9 -> 0.95), τ6 worst 0.654 (object; 0.65 -> 0.75), ORB
spread τ1 worst 0.415 (object; 0.45 -> 0.5), AKAZE τ4 worst 0.750 (object; 0.8 -> 0.85).

Re-measured when repeatability began to count the largest one-to-one matching instead of mutual nearest
neighbours only (pytest-n2r's ``result_version`` 2, docs/metrics.md "Repeatability: which points pair"). ORB
finds one corner at several pyramid levels, and mutual nearest neighbours lost both points of such a pair when
one moved a little: on the same examples (the baseline of main replayed with both matchings) the ORB
relations' mean deviation fell by 0.12-0.22 (τ1 0.308 -> 0.149 object, 0.324 -> 0.151 wall; τ4 0.532 ->
0.378, 0.501 -> 0.364), SIFT's and AKAZE's by at most 0.041. A relation's draws are keyed to its metric
and eps, so the new metric, and each new eps, draws other examples: the ORB eps went to 0.45-0.9 by the rule on
the first new draws, and those draws then broke τ2 and τ3 on the object (0.486, 0.542). So the ORB repeatability
eps come from 140 draws per relation and scene: those two sets of 20 and 100 more (``-o n2r_examples=100``, eps
0.99 so every draw is scored). Worst deviation (object / wall) and eps, the rule applied to the worst: τ1 0.420 /
0.259 (0.6 -> 0.5), τ2 0.532 / 0.325 (0.65 stays), τ3 0.542 / 0.432 (0.75 -> 0.65), τ4 0.843 / 0.564 (0.95
stays), τ5 0.396 / 0.288 (0.65 -> 0.5), τ6 0.495 / 0.305 (0.75 -> 0.6): the means fell by half, the object's
worst draws under large motions much less. SIFT and AKAZE keep their eps (worst on the first new draws τ1 SIFT
0.393 / 0.209, AKAZE 0.250 / 0.082; τ4 SIFT 0.537 / 0.275, AKAZE 0.714 / 0.333): the metric did not move them.

Re-measured on 6 December 2026, when the pose strategies stopped drawing the identity and the search stopped
counting an example drawn twice (pytest-n2r: a fifth of the 20 examples had been the identity, a view compared
with itself, and 3-8 more were repeats: 12-15 real tests a relation). On the new draws SIFT τ1 on the object broke
its eps (0.517 > 0.5), and five relations came within 0.08 of theirs; the exact scenes involve no fitted field, so
these are the detectors' own responses to motions the identity had stood in for. Each eps was set again by the rule
from the worst of all measurements: the 140 draws above, 100 draws per relation and scene on the new strategies
(``-o n2r_examples=100``, 22:38 UTC: object / wall ORB repeatability τ1 0.461 / 0.290, τ2 0.431 / 0.308, τ3 0.540
/ 0.406, τ4 0.807 / 0.569, τ5 0.539 / 0.299, τ6 0.532 / 0.334; spread τ1 0.415 / 0.286, τ2 0.627 / 0.363, τ3 0.554
/ 0.431, τ4 0.861 / 0.628, τ5 0.477 / 0.337, τ6 0.644 / 0.372; SIFT τ1 0.485 / 0.237, τ4 0.741 / 0.301; AKAZE τ1
0.250 / 0.152, τ4 0.667 / 0.484) and the 20-draw runs (SIFT τ1 0.517, ORB repeatability τ3 0.604). Raised: ORB
repeatability τ1 0.5 -> 0.55, τ3 0.65 -> 0.7, τ5 0.5 -> 0.65, τ6 0.6 -> 0.65; spread τ2 0.7 -> 0.75, τ4 0.9 -> 0.95,
τ5 0.55 -> 0.6, τ6 0.65 -> 0.75; SIFT τ1 0.5 -> 0.6. Lowered, being looser than the rule: SIFT τ4 0.9 -> 0.85
(worst 0.741), AKAZE τ1 0.5 -> 0.35 (0.250). On the shipped draws of these eps (the committed gate baseline) the
worst deviations (object / wall) are ORB repeatability τ1 0.353 / 0.189, τ2 0.560 / 0.310, τ3 0.481 / 0.342, τ4
0.795 / 0.611, τ5 0.310 / 0.270, τ6 0.373 / 0.277; spread τ1 0.395 / 0.244, τ2 0.548 / 0.370, τ3 0.491 / 0.403, τ4
0.832 / 0.573, τ5 0.411 / 0.291, τ6 0.440 / 0.342; SIFT τ1 0.401 / 0.224, τ4 0.592 / 0.261; AKAZE τ1 0.125 / 0.118,
τ4 0.583 / 0.347.
"""

from __future__ import annotations

import pytest
from perception.detectors import detector

from pytest_n2r import metamorphic
from pytest_n2r.metrics import interest_point_spread, repeatability

REPEATABILITY = repeatability(px=3)
SPREAD = interest_point_spread(radius=8)

pytestmark = pytest.mark.detectors


# -- ORB, the detector the robot runs (PERCEPTION_ORB selects a candidate configuration) ---------------------
@metamorphic(REPEATABILITY, eps=0.55, transform="tau1")
def test_orb_repeatability_tau1(n2r_scene, orb):
    return orb


@metamorphic(REPEATABILITY, eps=0.65, transform="tau2")
def test_orb_repeatability_tau2(n2r_scene, orb):
    return orb


@metamorphic(REPEATABILITY, eps=0.7, transform="tau3")
def test_orb_repeatability_tau3(n2r_scene, orb):
    return orb


@metamorphic(REPEATABILITY, eps=0.95, transform="tau4")
def test_orb_repeatability_tau4(n2r_scene, orb):
    return orb


@metamorphic(REPEATABILITY, eps=0.65, transform="tau5")
def test_orb_repeatability_tau5(n2r_scene, orb):
    return orb


@metamorphic(REPEATABILITY, eps=0.65, transform="tau6")
def test_orb_repeatability_tau6(n2r_scene, orb):
    return orb


@metamorphic(SPREAD, eps=0.5, transform="tau1")
def test_orb_spread_tau1(n2r_scene, orb):
    return orb


@metamorphic(SPREAD, eps=0.75, transform="tau2")
def test_orb_spread_tau2(n2r_scene, orb):
    return orb


@metamorphic(SPREAD, eps=0.65, transform="tau3")
def test_orb_spread_tau3(n2r_scene, orb):
    return orb


@metamorphic(SPREAD, eps=0.95, transform="tau4")
def test_orb_spread_tau4(n2r_scene, orb):
    return orb


@metamorphic(SPREAD, eps=0.6, transform="tau5")
def test_orb_spread_tau5(n2r_scene, orb):
    return orb


@metamorphic(SPREAD, eps=0.75, transform="tau6")
def test_orb_spread_tau6(n2r_scene, orb):
    return orb


# -- SIFT and AKAZE: the alternatives we keep an eye on (small and large motions) -------------------------------
@metamorphic(REPEATABILITY, eps=0.6, transform="tau1")
def test_sift_repeatability_tau1(n2r_scene):
    return detector("sift")


@metamorphic(REPEATABILITY, eps=0.85, transform="tau4")
def test_sift_repeatability_tau4(n2r_scene):
    return detector("sift")


@metamorphic(REPEATABILITY, eps=0.35, transform="tau1")
def test_akaze_repeatability_tau1(n2r_scene):
    return detector("akaze")


@metamorphic(REPEATABILITY, eps=0.85, transform="tau4")
def test_akaze_repeatability_tau4(n2r_scene):
    return detector("akaze")
