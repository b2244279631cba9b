"""The outputs of the paper's experiments (:mod:`pose_lifter.mocap.experiments`): per-sample and
aggregated CSV tables, markdown tables and PNG plots, from the workers' result rows.

Curves over a condition show mean P-MPJPE: the leg-unit error rescales each estimate by its own
right lower leg, so one short-legged estimate can dominate a mean over few poses (see the tables).
"""

from __future__ import annotations

import csv
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pose_lifter.mocap.experiment_tasks import VARIANTS

__all__ = ["aggregate", "cell", "exp1_output", "lift_output", "md_table", "write_csv"]


def write_csv(path: Path, rows: Sequence[dict[str, Any]], cols: Sequence[str]) -> None:
    """Write ``rows``' ``cols`` as CSV (floats to 4 decimals, missing values empty)."""
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(cols), extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({c: (f"{r[c]:.4f}" if isinstance(r.get(c), float) else r.get(c, "")) for c in cols})


def md_table(rows: Sequence[dict[str, Any]], cols: Sequence[str], heads: Sequence[str] | None = None) -> str:
    """A markdown table of ``rows``' ``cols`` under ``heads`` (default: the column names)."""
    heads = list(heads or cols)

    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return "nan" if not np.isfinite(v) else (f"{v:.1f}" if abs(v) >= 10 else f"{v:.3f}")
        return str(v)

    lines = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    lines += ["| " + " | ".join(fmt(r.get(c, "")) for c in cols) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def aggregate(rows: Sequence[dict[str, Any]], keys: Sequence[str]) -> list[dict[str, Any]]:
    """One row per value of ``keys``: counts, mean and median errors of its finite rows, mean time."""
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[tuple(r[k] for k in keys)].append(r)
    out = []
    for key, rs in groups.items():
        e = np.array([r["err"] for r in rs], float)
        m = np.array([r["pmpjpe_mm"] for r in rs], float)
        ok = np.isfinite(e)
        out.append({**dict(zip(keys, key, strict=True)), "n": int(ok.sum()), "failed": int((~ok).sum()),
                    "err_mean": float(e[ok].mean()) if ok.any() else float("nan"),
                    "err_median": float(np.median(e[ok])) if ok.any() else float("nan"),
                    "pmpjpe_mean": float(m[ok].mean()) if ok.any() else float("nan"),
                    "pmpjpe_median": float(np.median(m[ok])) if ok.any() else float("nan"),
                    "time_s": float(np.mean([r["time_s"] for r in rs]))})
    return out


_MM_LABEL = "mean P-MPJPE (mm, similarity-aligned)"


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _method_order(names: Iterable[str]) -> list[str]:
    order = [*VARIANTS, "Ramakrishna", "flat floor", "mean-pose floor"]
    names = set(names)
    return [n for n in order if n in names] + sorted(n for n in names if n not in order)


def _style(name: str) -> dict[str, Any]:
    if name.endswith("floor"):
        return {"color": "0.6", "ls": ":" if name.startswith("flat") else "--", "lw": 1.2}
    if name == "Ramakrishna":
        return {"color": "k", "ls": "-.", "lw": 1.8}
    if name == "L1WAWS":
        return {"color": "C3", "lw": 2.4}
    return {"lw": 1.2, "ls": "-" if name.startswith("L1") else "--"}


def _cdf(ax: Any, values: NDArray[np.float64], label: str, **kw: Any) -> None:
    v = np.sort(values[np.isfinite(values)])
    if len(v):
        ax.step(np.r_[0.0, v], np.r_[0.0, np.arange(1, len(v) + 1) / len(v)], where="post", label=label, **kw)


def exp1_output(out: Path, rows: list[dict[str, Any]], n_test: int, intro: str) -> str:
    """Experiment 1's CSV, plot and markdown (``intro``: its first paragraph); the markdown."""
    plt = _plt()
    rows = sorted(rows, key=lambda r: (r["method"], r["k"]))
    cols = ["method", "k", "err", "err_median", "mpjpe_mm", "active_mean", "failed"]
    write_csv(out / "exp1_bases.csv", rows, cols)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    for m, st in (("sparse", "C3-o"), ("PCA", "C0-s"), ("class-wise PCA", "C2-^")):
        rs = [r for r in rows if r["method"] == m and not r["failed"]]
        if not rs:
            continue
        a1.plot([r["k"] for r in rs], [r["err"] for r in rs], st, label=m, ms=4)
        biggest = max(rs, key=lambda r: r["k"])
        _cdf(a2, np.asarray(biggest["active"], float), f"{m} (k={biggest['k']})", color=st[:2])
    a1.set(xlabel="number of bases k", ylabel="reconstruction error ||y - y_hat||_2 (leg units)",
           title=f"Fig. 3a: unseen test poses (n={n_test})", xscale="log")
    a2.set(xlabel="active bases per pose", ylabel="fraction of poses", title="Fig. 3b: active bases (CDF)")
    for a in (a1, a2):
        a.grid(alpha=0.3)
        a.legend()
    fig.tight_layout()
    fig.savefig(out / "exp1_bases.png", dpi=90)
    plt.close(fig)
    md = f"### 1. Basis learning (Fig. 3)\n\n{intro}\n\n"
    heads = ["method", "k", "error (leg)", "median", "MPJPE mm", "active bases (mean)"]
    md += md_table(rows, cols[:-1], heads)
    (out / "exp1_bases.md").write_text(md)
    return md


def lift_output(out: Path, name: str, rows: list[dict[str, Any]], keys: list[str], title: str,
                 intro: str) -> tuple[str, list[dict[str, Any]]]:
    """One lift experiment's per-sample and aggregated CSVs (aggregated by ``keys``), markdown and
    plot; the markdown and the aggregated rows."""
    plt = _plt()
    write_csv(out / f"{name}_raw.csv", rows, ["exp", "cond", "level", "pose", "src", "yaw", "method", "err",
                                              "pmpjpe_mm", "time_s", "failed"])
    agg = aggregate(rows, keys)
    order = _method_order(r["method"] for r in agg)
    agg.sort(key=lambda r: (*(r[k] for k in keys if k != "method"), order.index(r["method"])))
    cols = [*keys, "n", "failed", "err_mean", "err_median", "pmpjpe_mean", "pmpjpe_median", "time_s"]
    write_csv(out / f"{name}.csv", agg, cols)
    heads = [*keys, "n", "failed", "error mean (leg)", "error median", "P-MPJPE mean mm", "P-MPJPE median mm",
             "s/pose"]
    md = f"### {title}\n\n{intro}\n\n" + md_table(agg, cols, heads)
    (out / f"{name}.md").write_text(md)
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    if keys == ["method"]:  # cumulative distributions
        for m in order:
            _cdf(ax, np.array([r["err"] for r in rows if r["method"] == m], float), m, **_style(m))
        ax.set(xlabel="||y - y_hat||_2 (right lower leg units)", ylabel="fraction of poses")
    elif name == "exp3_robust":
        conds = list(dict.fromkeys((r["cond"], r["level"]) for r in agg))
        xs = np.arange(len(conds))
        for m in order:
            cell = {(r["cond"], r["level"]): r["pmpjpe_mean"] for r in agg if r["method"] == m}
            ys = [cell.get(c, np.nan) for c in conds]
            ax.plot(xs, ys, marker="o", label=m, **_style(m))
        ax.set_xticks(xs, [c if c == "clean" else f"{int(n)} {c}" for c, n in conds], rotation=20)
        ax.set(ylabel=_MM_LABEL)
    else:
        for m in order:
            rs = sorted((r for r in agg if r["method"] == m), key=lambda r: r["level"])
            ax.plot([r["level"] for r in rs], [r["pmpjpe_mean"] for r in rs], marker="o", ms=3, label=m,
                    **_style(m))
        ax.set(xlabel="2D noise std (right lower leg units)" if name == "exp3_noise" else "yaw (degrees)",
               ylabel=_MM_LABEL)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out / f"{name}.png", dpi=90)
    plt.close(fig)
    return md, agg


def cell(agg: list[dict[str, Any]], method: str, col: str = "err_mean", **where: Any) -> float:
    """``col`` of ``method``'s aggregated row matching ``where`` (NaN when there is none)."""
    for r in agg:
        if r["method"] == method and all(r.get(k) == v for k, v in where.items()):
            return float(r[col])
    return float("nan")
