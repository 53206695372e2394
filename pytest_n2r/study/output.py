"""Writing a :class:`~pytest_n2r.study.run.StudyResult`: CSV tables, a Markdown summary, PNG plots."""

from __future__ import annotations

import csv
import io
import math
import os
from collections import defaultdict
from pathlib import Path

import numpy as np

from ..data.atomic import atomic_write_bytes, atomic_write_text
from .correlation import ALPHA, can_be_significant
from .run import StudyResult

__all__ = ["write_study", "markdown_table", "PLOTS"]

#: The plots a study may draw (one is left out when its table is empty, all when matplotlib is missing).
PLOTS = ("rq1_realness.png", "rq2_inconsistencies.png", "rq3_fps.png")


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return "—" if math.isnan(value) else f"{value:.4g}"
    return "—" if value is None else str(value)


def markdown_table(rows: list[dict], columns: list[str] | None = None) -> str:
    """Rows of dicts as a Markdown table (floats to 4 significant digits, NaN/None as —)."""
    if not rows:
        return "_no rows_\n"
    columns = columns or list(rows[0])
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_fmt(r.get(c)) for c in columns) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    if rows:
        writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return buf.getvalue()


def _mean_by(rows: list[dict], keys: tuple[str, ...], values: tuple[str, ...]) -> list[dict]:
    """The mean of each of ``values`` per group of ``keys`` over the group's rows not marked invalid whose value
    is defined (NaN where none is): ``n`` counts the group's rows, ``n_valid`` its rows not marked invalid
    (``valid`` false; a row without ``valid``, such as a realness row, is not marked, so it counts)."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        groups[tuple(r[k] for k in keys)].append(r)
    out = []
    for key, members in sorted(groups.items()):
        row = dict(zip(keys, key))
        for v in values:
            xs = [m[v] for m in members if m.get(v) is not None and not math.isnan(m[v]) and m.get("valid", True)]
            row[v] = float(np.mean(xs)) if xs else float("nan")
        row["n"] = len(members)
        row["n_valid"] = sum(bool(m.get("valid", True)) for m in members)
        out.append(row)
    return out


def summary_markdown(result: StudyResult) -> str:
    """The study as one Markdown document: RQ1, RQ2, RQ3 tables and notes."""
    parts = ["# n2r study\n"]
    parts += ["## RQ1 — realness (mean over views; reference: the real photo)\n",
              markdown_table(_mean_by(result.realness, ("scene", "source"), ("psnr", "ssim", "lpips"))),
              "\n### SUT metrics under the reality-to-field shift (τ0)\n",
              markdown_table(_mean_by(result.domain_shift, ("scene", "sut", "metric"), ("score", "deviation"))),
              "\n### Image quality against the SUT metrics (Spearman, τ0 over the views)\n",
              _dependence(result.correlations), markdown_table(result.correlations)]
    parts += ["\n## RQ2 — inconsistencies per SUT, metric and transform family\n",
              markdown_table(result.inconsistencies)]
    parts += ["\n## RQ3 — rendering speed (RGB only)\n", markdown_table(result.fps)]
    if result.notes:
        parts += ["\n## Notes\n", "".join(f"- {n}\n" for n in result.notes)]
    return "\n".join(parts)


def _dependence(rows: list[dict]) -> str:
    """How many combinations show a dependence, out of those with a rank correlation (the paper: 38 of 48)."""
    if not rows:
        return ("No view paired a field's render with a real photo (exact scenes, or no stored photos): nothing to "
                "correlate.\n\n")
    ranked = [r for r in rows if not math.isnan(r["rho"])]
    significant = sum(r["significant"] for r in ranked)
    unranked = (f"; {len(rows) - len(ranked)} without one (fewer than 3 views with both values, e.g. LPIPS not "
                f"measured, or all values equal)") if len(ranked) < len(rows) else ""
    few = sum(not can_be_significant(r["n"]) for r in ranked)
    too_few = (f"; {few} of them on too few views to reach p < {ALPHA:g} at all (fewer than 5: raise --views)"
               if few else "")
    return (f"{significant} of {len(ranked)} combinations with a rank correlation are significant at p < {ALPHA:g} "
            f"(the paper: 38 of 48){too_few}{unranked}.\n\n")


def _plots(result: StudyResult, out: Path) -> list[str]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return ["plots skipped: matplotlib is not installed (pip install 'pytest-n2r[study]')"]
    written = []
    realness_png, inconsistencies_png, fps_png = PLOTS

    def save(fig, name: str) -> None:
        buf = io.BytesIO()
        fig.tight_layout()
        fig.savefig(buf, format="png", dpi=110)
        plt.close(fig)
        atomic_write_bytes(out / name, buf.getvalue())
        written.append(name)

    realness = _mean_by(result.realness, ("source",), ("psnr", "ssim"))
    if realness:
        fig, axes = plt.subplots(1, 2, figsize=(8, 3))
        for ax, key in zip(axes, ("psnr", "ssim")):
            values = [r[key] for r in realness]
            finite = [v for v in values if math.isfinite(v)] or [1.0]
            cap = max(finite) * 1.25  # identical images have infinite PSNR: draw them at the cap, labelled
            bars = ax.bar([r["source"] for r in realness], [v if math.isfinite(v) else cap for v in values],
                          color=["#d62728" if r["source"] == "tau0" else "#1f77b4" for r in realness])
            ax.bar_label(bars, ["∞" if not math.isfinite(v) else f"{v:.3g}" for v in values], fontsize=7)
            ax.set_title(f"RQ1 {key.upper()} vs real photo")
        save(fig, realness_png)
    incs = result.inconsistencies
    if incs and result.eps:
        metrics = sorted({r["metric"] for r in incs})
        fig, axes = plt.subplots(1, len(metrics), figsize=(3.2 * len(metrics), 3), squeeze=False)
        for ax, metric in zip(axes[0], metrics):
            for offset, kind, colour in ((-0.2, "n2r", "#d62728"), (0.2, "mutation", "#1f77b4")):
                rows = [r for r in incs if r["metric"] == metric and r["kind"] == kind and r["valid"]]
                counts = [sum(r[f"inc@{e:g}"] for r in rows) for e in result.eps]  # no valid example: no count
                valid = sum(r["valid"] for r in rows)
                bars = ax.bar(np.arange(len(result.eps)) + offset, counts, width=0.4, color=colour,
                              label="N2R τ1–τ6" if kind == "n2r" else "mutations m1–m3")
                # six pose families against three mutation families, fewer valid pose draws: the bars' counts
                # are of different totals, so each says of how many valid examples it is
                ax.bar_label(bars, [f"{c}/{valid}" for c in counts], fontsize=6)
            ax.set_xticks(range(len(result.eps)), [f"ε={e:g}" for e in result.eps])
            ax.set_title(metric)
        axes[0][0].legend(fontsize=7)
        save(fig, inconsistencies_png)
    if result.fps:
        fig, ax = plt.subplots(figsize=(5, 3))
        labels = [f"{r['scene']}\n{r['width']}×{r['height']}" for r in result.fps]
        ax.bar(labels, [r["fps"] for r in result.fps], color="#2ca02c")
        ax.set_ylabel("frames / s")
        ax.set_title("RQ3 render speed")
        save(fig, fps_png)
    return written


def write_study(result: StudyResult, out: str | os.PathLike) -> list[Path]:
    """Write CSVs (one per table), ``study.md`` and PNG plots into ``out``; return the paths written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tables = {"realness": result.realness, "domain_shift": result.domain_shift, "examples": result.examples,
              "inconsistencies": result.inconsistencies, "correlations": result.correlations, "fps": result.fps}
    paths = [atomic_write_text(out / f"{name}.csv", _csv(rows)) for name, rows in tables.items()]
    notes = _plots(result, out)
    for name in PLOTS:  # a plot this run did not draw is not left from an earlier run into the same folder
        if name not in notes:
            (out / name).unlink(missing_ok=True)
    if notes:
        result.notes.extend(n for n in notes if n.startswith("plots skipped"))
        paths += [out / n for n in notes if n.endswith(".png")]
    paths.append(atomic_write_text(out / "study.md", summary_markdown(result)))
    return paths
