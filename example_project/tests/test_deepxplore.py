"""The 2-D comparison: DeepXplore's image mutations (m1 brightness, m2 a noise patch, m3 black patches on
the lens) applied to the rendered source view, with the same metrics as the pose transforms.

``eps`` as in test_detectors.py: the measured worst deviation rounded up. A noise patch over up to 30 % of
the image draws ORB's 500-keypoint budget into the noise: up to 69 % of the source keypoints were not found
again (measured on both demo scenes), a weakness the pose transforms τ1/τ2 do not show. On the examples drawn
since pytest-n2r's derandomized search stopped depending on the loaded modules (issue 15), up to 83 % (wall;
eps 0.8 -> 0.95 to keep the 0.08 margin of test_detectors.py).

Since repeatability counts the largest one-to-one matching (``result_version`` 2, test_detectors.py says why), the
same examples replayed with both matchings moved little under these mutations: mean deviation −0.004 to −0.014,
worst −0.088 at most (brightness on the object, 0.241 -> 0.153). On the draws of the new metric the worst
deviations are brightness 0.183 / 0.365, noise patch 0.720 / 0.694, black patches 0.085 / 0.090 (object / wall):
eps unchanged, each at least 0.08 above them.

Re-measured on 6 December 2026, when the mutation strategies stopped drawing a mutation that changes nothing and
the search stopped counting an example drawn twice: over 100 draws per relation and scene (``-o n2r_examples=100``)
the worst ORB deviations are brightness 0.221 / 0.459, noise patch 0.818 / 0.849, black patches 0.102 / 0.133
(object / wall). Brightness (0.75) and black patches (0.5) were far looser than the rule and are now 0.55 and 0.25;
the noise patch keeps 0.95. On the shipped draws: brightness 0.146 / 0.447, noise patch 0.826 / 0.662, black
patches 0.072 / 0.101. MobileNetV2's top-5 invariance held on every shipped draw, but 3 of the 100 draws of black
patches moved its top-1 class out of the follow-up's top 5 (deviation 1): the relation stood as the SUT's
measured behaviour on these 20 examples, not a guarantee; a larger search finds that weakness.

On 7 December 2026 the grid's draws changed (every drawn choice used, so shrinking reaches the smallest failing
motion; the spread of the draws kept): the shipped 20 draws of black patches now include 3 that move MobileNetV2's
top-1 class out of its top 5 (2 of 100 draws with ``-o n2r_examples=100``), the weakness measured above. The
relation is kept, marked as an expected failure (``xfail``, strict: a run in which it held would fail and ask
for a look), not loosened: no eps below 1 passes a lost class, and narrowing the patches would hide what the
SUT does. The ORB relations' worst deviations on the new shipped draws (object / wall): brightness 0.146 / 0.447,
noise patch 0.703 / 0.794, black patches 0.078 / 0.073 (0.120 / 0.108 over 100 draws): eps unchanged.
"""

from __future__ import annotations

import pytest

from pytest_n2r import metamorphic
from pytest_n2r.metrics import class_invariance, repeatability
from pytest_n2r.strategies import black_patches, brightness, noise_patch

from .conftest import load_classifier, skip_without_object


@pytest.mark.detectors
@metamorphic(repeatability(px=3), eps=0.55, transform=brightness(max_levels=64))
def test_orb_repeatability_m1_brightness(n2r_scene, orb):
    return orb


@pytest.mark.detectors
@metamorphic(repeatability(px=3), eps=0.95, transform=noise_patch(max_size=0.3))
def test_orb_repeatability_m2_noise_patch(n2r_scene, orb):
    return orb


@pytest.mark.detectors
@metamorphic(repeatability(px=3), eps=0.25, transform=black_patches(max_size=0.05, count=4))
def test_orb_repeatability_m3_black_patches(n2r_scene, orb):
    return orb


@pytest.mark.classifiers
@metamorphic(class_invariance(top_k=5), eps=0.0, transform=brightness(max_levels=32))
def test_mobilenet_class_invariance_m1_brightness(n2r_scene):
    skip_without_object(n2r_scene)
    return load_classifier("mobilenet_v2")


@pytest.mark.classifiers
@metamorphic(class_invariance(top_k=5), eps=0.0, transform=black_patches(max_size=0.05, count=4))
def test_mobilenet_class_invariance_m3_black_patches(n2r_scene, request):
    skip_without_object(n2r_scene)
    if n2r_scene.name == "object":  # the exact demo scene: its draws are the measured ones (module docstring)
        request.applymarker(pytest.mark.xfail(
            strict=True, reason="MobileNetV2's top-1 class leaves its top 5 under four black patches of up to 5 % "
            "(3 of the 20 shipped draws, 2 of 100; module docstring): the weakness of the SUT found here"))
    return load_classifier("mobilenet_v2")
