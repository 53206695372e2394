"""Results of metamorphic relations as plain data: baselines, paired comparisons, HTML and JSON reports.

Nothing here imports pytest or torch: everything reads the relation engine's records
(:class:`~pytest_n2r.relation.record.RelationRecord`, :class:`~pytest_n2r.relation.record.ExampleRecord`, also
importable from here), which the plugin gathers and hands over.
"""

from ..relation.record import ExampleRecord, RelationRecord
from .baseline import BaselineError, load_baseline, save_baseline
from .compare import PairedComparison, compare_paired, parse_margin, parse_outcomes, replay_candidates

__all__ = [
    "ExampleRecord", "RelationRecord", "save_baseline", "load_baseline", "BaselineError", "PairedComparison",
    "compare_paired", "parse_margin", "parse_outcomes", "replay_candidates",
]
