"""The pytest plugin (registered through the ``pytest11`` entry point as ``n2r``; ``-p no:n2r`` disables it).

Thin and lazy: heavy imports happen inside hooks and fixtures, only when a test uses pytest-n2r.
"""

from __future__ import annotations
