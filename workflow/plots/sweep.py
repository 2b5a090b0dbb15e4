"""The pictures of a sweep (``OUT/sweep.html``): each figure against each parameter, and the Pareto
front of beam mass against the worst non-linear load factor. One self-contained HTML page."""

from __future__ import annotations

import base64
import html

import numpy as np

from fabrication.files import figure_png

from ..labels import format_value
from ._common import pyplot

__all__ = ["sweep_html", "pareto_front", "PLOTTED"]

#: Figures plotted against the parameters, with their axis labels.
PLOTTED = {"lambda_NL_worst": "worst non-linear load factor", "lambda_LB": "linear buckling load factor",
           "delta_L_m": "SLS deflection (m)", "max_utilisation": "max utilisation",
           "beam_mass_kg": "beam mass (kg)", "total_beam_length_m": "total beam length (m)"}


def pareto_front(mass: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """(n,) whether each point is on the Pareto front of low ``mass`` and high ``factor`` (no other
    point is at least as light and at least as strong, and better in one). NaN is never on it."""
    mass, factor = np.asarray(mass, float), np.asarray(factor, float)
    valid = np.isfinite(mass) & np.isfinite(factor)
    out = np.zeros(len(mass), dtype=bool)
    for i in np.flatnonzero(valid):
        others = valid & (mass <= mass[i]) & (factor >= factor[i]) & ((mass < mass[i]) | (factor > factor[i]))
        out[i] = not others.any()
    return out


def _png(fig) -> str:
    plt = pyplot()
    data = figure_png(fig, dpi=110)
    plt.close(fig)
    return base64.b64encode(data).decode("ascii")


def _numeric(values) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


def _against(frame, key: str, others: list[str]) -> str:
    """One row of small plots: every plotted figure against ``key``, one line per combination of
    the ``others``."""
    plt = pyplot()
    figures = [f for f in PLOTTED if f in frame and frame[f].notna().any()]
    fig, axes = plt.subplots(1, max(len(figures), 1), figsize=(3.2 * max(len(figures), 1), 2.9), squeeze=False)
    values = list(dict.fromkeys(frame[key]))
    numeric = _numeric(values)
    position = {v: i for i, v in enumerate(values)}
    groups = frame.groupby(others, dropna=False, sort=False) if others else [((), frame)]
    for ax, figure in zip(axes[0], figures):
        for label, group in groups:
            ok = group[group["status"] == "ok"].sort_values(key) if numeric else group[group["status"] == "ok"]
            x = ok[key].to_numpy(float) if numeric else np.array([position[v] for v in ok[key]], float)
            name = ", ".join(f"{k} {format_value(v, text=True)}" for k, v in
                             zip(others, label if isinstance(label, tuple) else (label,)))
            ax.plot(x, ok[figure].to_numpy(float), "o-", ms=4, lw=1, label=name or None)
        if not numeric:
            ax.set_xticks(range(len(values)), [str(v) for v in values])
        ax.set_xlabel(key, fontsize=8)
        ax.set_ylabel(PLOTTED[figure], fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    if others and len(groups) <= 8:
        axes[0][0].legend(fontsize=6)
    fig.tight_layout()
    return _png(fig)


def _pareto(frame) -> str | None:
    if not {"beam_mass_kg", "lambda_NL_worst"} <= set(frame) or not frame["lambda_NL_worst"].notna().any():
        return None
    plt = pyplot()
    mass, factor = frame["beam_mass_kg"].to_numpy(float), frame["lambda_NL_worst"].to_numpy(float)
    front = pareto_front(mass, factor)
    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    ax.scatter(mass[~front], factor[~front], s=18, c="#9ecae1", label="points")
    order = np.argsort(mass[front])
    ax.plot(mass[front][order], factor[front][order], "o-", c="#08519c", ms=5, label="Pareto front")
    for m, f, number in zip(mass[front], factor[front], frame["point"].to_numpy()[front]):
        ax.annotate(f"{int(number)}", (m, f), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.set_xlabel("beam mass (kg)")
    ax.set_ylabel("worst non-linear load factor")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _png(fig)


def sweep_html(frame, keys: list[str], *, title: str) -> str:
    """The sweep's page: the status counts, a plot row per parameter key, the Pareto front of mass
    against lambda_NL_worst, and the table of the points."""
    ok = int((frame["status"] == "ok").sum())
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}: sweep</title>",
             "<style>body{font-family:sans-serif;margin:24px;max-width:1400px}img{max-width:100%}"
             "table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px;"
             "text-align:right}.failed{color:#b00}</style></head><body>",
             f"<h1>{html.escape(title)}: {len(frame)} points, {ok} ok, {len(frame) - ok} failed</h1>"]
    plotted = [f for f in PLOTTED if f in frame and frame[f].notna().any()]
    if ok and not plotted:
        parts.append("<p>No figures to plot: the sweep stops before the analysis (until).</p>")
    if ok and plotted:
        for key in keys:
            others = [k for k in keys if k != key and frame[k].nunique() > 1]
            parts.append(f"<h2>Against {html.escape(key)}</h2><img alt='figures against {html.escape(key)}' "
                         f"src='data:image/png;base64,{_against(frame, key, others)}'>")
        pareto = _pareto(frame)
        if pareto:
            parts.append("<h2>Mass against the worst non-linear load factor</h2><p>The Pareto front: no other point "
                         "is lighter and at least as strong. Labels are point numbers.</p>"
                         f"<img alt='Pareto front' src='data:image/png;base64,{pareto}'>")
    columns = [c for c in frame.columns if c != "folder"]
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
    body = []
    for _, row in frame.iterrows():
        css = "" if row["status"] == "ok" else " class='failed'"
        cells = "".join(f"<td>{html.escape(format_value(row[c]))}</td>"
                        for c in columns)
        body.append(f"<tr{css}>{cells}</tr>")
    parts.append(f"<h2>Points</h2><table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>")
    parts.append("</body></html>")
    return "".join(parts)
