"""Results of metamorphic relations as plain data: baselines, comparisons, HTML and JSON reports.

Nothing here imports pytest or torch: the plugin fills :class:`RelationRecord` objects and hands them over.
"""

from .baseline import CompareRule, Comparison, compare_runs, load_baseline, parse_compare_rules, save_baseline
from .records import ExampleRecord, RelationRecord

__all__ = [
    "ExampleRecord", "RelationRecord", "save_baseline", "load_baseline", "CompareRule", "Comparison",
    "parse_compare_rules", "compare_runs",
]
