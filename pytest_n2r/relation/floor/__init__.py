"""The field floor: what a fitted scene's field alone does to a SUT's metric (the paper's reality-to-field
shift), measured once per scene, SUT, metric and render size, and cached.

For every held-out view of a fitted scene, the SUT runs on the view's *reference image* and on the field's
render at the same pose and size, and the metric compares the two outputs as if they were a relation's
source and follow-up. The reference image is, in this order:

- ``"photo"``: the real photo the scene file stores (``n2r fit`` stores a JPEG copy of every photo unless
  ``--no-images``), resized to the render size;
- ``"exact"``: for a fitted demo scene (``demo:wall-field``), the exact scene's render at the same pose:
  the truth the field was fitted to.

An exact scene has no field, so no floor; a fitted scene without photos or exact twin has no reference.
Both are reported as unavailable with the reason, never as a floor of 0.

The floor is the mean deviation over the held-out views whose metric is defined. Beside it, the same SUT and
metric between each reference image and the capture's nearest other fitted view's reference image brought to the
pose through the field's depth (:mod:`.nearby`): what an image taken nearby gives, so a floor is read against what
the capture itself allows (a photo scene's floor near it is the photos', not the field's). A relation whose ``eps``
is below it asks the SUT to agree with itself across two renders more closely than it agrees between the
photo and the render of one pose: it then tests the scene field, not the SUT.

Only held-out views count: the field was fitted to the training photos, so their shift understates what
the field does at the new poses relations render.

Convention
    Deviations are the metric's (``|score - ideal|``, larger is worse), unitless. Render sizes follow
    :class:`~pytest_n2r.render.size.RenderSize` (``None``: each view's own camera).
"""

from __future__ import annotations

from .annotate import annotate_relation, annotation_lines
from .exact import EXACT_REPLAY_EXAMPLES, ExactComparison, compare_exact
from .measure import FLOOR_VERSION, FieldFloor, FloorStore, json_number, measure_floor, sut_name
from .reference import ShiftSample, exact_twin, floor_views, reference_image, reference_kind, shift_sample

__all__ = [
    "ExactComparison",
    "FieldFloor",
    "FloorStore",
    "ShiftSample",
    "annotate_relation",
    "annotation_lines",
    "compare_exact",
    "exact_twin",
    "floor_views",
    "json_number",
    "measure_floor",
    "reference_image",
    "reference_kind",
    "shift_sample",
    "sut_name",
    "EXACT_REPLAY_EXAMPLES",
    "FLOOR_VERSION",
]
