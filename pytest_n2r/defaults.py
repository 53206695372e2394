"""The defaults that more than one layer uses, written once.

The pytest plugin shows them in ``--help`` and parses them like a value the user typed; the library objects
(:class:`~pytest_n2r.relation.RunSettings`, :class:`~pytest_n2r.RenderCache`, the plugin's session, the
baseline comparison) take them as the defaults of their arguments. A leaf module: it imports nothing, so the
plugin reads it at start-up without loading the engine.
"""

from __future__ import annotations

#: Hypothesis examples per relation (``--n2r-examples``, ``RunSettings.examples``).
EXAMPLES = 50
#: Seconds one render or one SUT call may take; ``None`` or 0: no limit (``--n2r-timeout``, ``RunSettings.timeout``).
TIMEOUT_S = 300.0
#: Disk cap of the render cache (``--n2r-cache-size``, ``RenderCache(disk_bytes=...)``).
CACHE_SIZE = "2GiB"
#: Where scene fields render: ``auto`` (CUDA when available), ``cpu``, ``cuda``, ``cuda:N`` (``--n2r-device``).
DEVICE = "auto"
#: Scene fields render at this fraction of the render size, upsampled to it (``--n2r-render-scale``).
RENDER_SCALE = 1.0
#: The baseline gate fails a relation when the lower confidence bound of the mean paired increase of its
#: deviation exceeds this margin (``--n2r-compare-fail mean:MARGIN``).
COMPARE_MARGIN = 0.02
#: Confidence of that one-sided bound (``--n2r-compare-confidence``).
COMPARE_CONFIDENCE = 0.95
#: Comparison outcomes that fail the run (``--n2r-compare-fail-on``).
COMPARE_FAIL_ON = ("worse", "lost", "no-pairs", "changed-scene", "changed-metric", "missing")
