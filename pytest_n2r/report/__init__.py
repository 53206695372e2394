"""Results of metamorphic relations as plain data: baselines, paired comparisons, HTML and JSON reports.

Nothing here imports pytest or torch: the plugin fills :class:`RelationRecord` objects and hands them over.
"""

from .baseline import (
    BaselineError,
    PairedComparison,
    compare_paired,
    load_baseline,
    parse_margin,
    parse_outcomes,
    replay_candidates,
    save_baseline,
)
from .records import ExampleRecord, RelationRecord

__all__ = [
    "ExampleRecord", "RelationRecord", "save_baseline", "load_baseline", "BaselineError", "PairedComparison",
    "compare_paired", "parse_margin", "parse_outcomes", "replay_candidates",
]
