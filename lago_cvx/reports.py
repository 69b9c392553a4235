"""Short, bounded text for results: ``short_repr`` (what ``repr(result)`` prints — a few lines whatever the
graph's size) and ``Summary`` (what ``result.summary()`` returns — a dict of JSON-ready values that prints
as a small two-column table, as statsmodels' ``summary()`` does).

The results hold arrays of n poses and m edges; their dataclass ``repr`` would print them all (about
12 700 characters on a 1 000-pose graph, megabytes on a large one). Every line here is built from
counts, a few scalars and the timings, and ``short_repr`` caps the whole at ``REPR_LIMIT`` characters."""

from __future__ import annotations

import textwrap

import numpy as np

__all__ = ["REPR_LIMIT", "Summary", "fmt_value", "fmt_timings", "refine_repr", "refine_summary", "short_repr"]

#: No ``repr`` of a result is longer than this (characters).
REPR_LIMIT = 2000
#: Width of a summary table and of a wrapped ``repr`` line (columns).
WIDTH = 78


def fmt_value(v) -> str:
    """One value as table text: floats to 7 significant digits, booleans as yes/no, None as "—"."""
    if v is None:
        return "—"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.7g}"
    if isinstance(v, (list, tuple)) and len(v) > 6:
        return ", ".join(str(x) for x in v[:5]) + f", … ({len(v)} in all)"
    if isinstance(v, (list, tuple)):
        return ", ".join(str(x) for x in v) if v else "none"
    return str(v)


def fmt_timings(timings: dict, *, total_key: str = "total") -> str:
    """``"0.061 s (tree 0.002, regularization 0.010, …)"``: the total first, then each step [s]."""
    t = {k: float(v) for k, v in (timings or {}).items() if isinstance(v, (int, float, np.floating))}
    total = t.pop(total_key, sum(t.values()))
    parts = ", ".join(f"{k} {v:.3g}" for k, v in t.items())
    return f"{total:.3g} s" + (f" ({parts})" if parts else "")


def short_repr(kind: str, head: str, lines=()) -> str:
    """``<kind head\\n  line\\n  line>``, each line wrapped at ``WIDTH`` columns, the whole cut to
    ``REPR_LIMIT`` characters (an ellipsis marks a cut)."""
    out = textwrap.wrap(f"<{kind} {head}".rstrip(), WIDTH, subsequent_indent="    ")
    for line in lines:
        out += textwrap.wrap(line, WIDTH, initial_indent="  ", subsequent_indent="    ") or [""]
    text = "\n".join(out) + ">"
    if len(text) > REPR_LIMIT:
        text = text[:REPR_LIMIT - 2] + "…>"
    return text


class Summary(dict):
    """A result's summary: a ``dict`` of JSON-ready values (``summary()["chi2"]`` works as before) that
    prints (``str``, ``repr``) as a small table: a title, the values in two columns under their labels,
    the timings below.

    ``Summary(title, rows, timings=None)`` with ``rows`` a list of ``(key, label, value)``: ``key`` the
    dict key, ``label`` the table's words for it; ``timings`` a dict of seconds per step (stored under
    ``"timings"``)."""

    def __init__(self, title: str, rows, *, timings: dict | None = None):
        rows = list(rows)
        super().__init__((key, value) for key, _, value in rows)
        if timings is not None:
            self["timings"] = dict(timings)
        self.title = title
        self.labels = [(key, label) for key, label, _ in rows]

    def table(self) -> str:
        """The table as text (at most ``WIDTH`` columns): short values in two columns, long ones (a reason,
        a list) on full-width lines below them."""
        col_w = (WIDTH - 3) // 2
        cells, wide = [], []
        for key, label in self.labels:
            if key in self:
                value = fmt_value(self[key])
                (cells if len(label) + len(value) + 2 <= col_w else wide).append((label, value))
        half = (len(cells) + 1) // 2
        cols = [cells[:half], cells[half:]]

        def cell(label, value):
            return f"{label}:".ljust(col_w - len(value)) + value

        body = []
        for i in range(half):
            left = cell(*cols[0][i])
            right = cell(*cols[1][i]) if i < len(cols[1]) else ""
            body.append((left + "   " + right).rstrip())
        for label, value in wide:
            body += textwrap.wrap(f"{label}: {value}", WIDTH, subsequent_indent="    ")
        rule = "=" * WIDTH
        out = [self.title[:WIDTH].center(WIDTH).rstrip(), rule, *body]
        if "timings" in self:
            out.append("-" * WIDTH)
            out += textwrap.wrap("time: " + fmt_timings(self["timings"]), WIDTH, subsequent_indent="      ")
        out.append(rule)
        return "\n".join(out)

    def __str__(self) -> str:
        return self.table()

    __repr__ = __str__

    def __reduce__(self):  # pickles as what it is (dict subclasses would otherwise lose title and labels)
        rows = [(key, label, self[key]) for key, label in self.labels]
        return (_rebuild, (self.title, rows, self.get("timings"), dict(self)))


def _rebuild(title, rows, timings, data):
    s = Summary(title, rows, timings=timings)
    s.update(data)
    return s


def refine_repr(res) -> str:
    """``repr`` of a ``lago_cvx.refinement.RefineResult`` (fields ``poses``, ``chi2``, ``chi2_initial``,
    ``iterations``, ``converged``, ``reason``, ``method``, ``anchor``, ``backend``, ``log``)."""
    t = res.log[-1]["time"] if res.log else float("nan")
    return short_repr(type(res).__name__, f"{_n_poses(res)} poses: χ² {res.chi2_initial:.10g} → {res.chi2:.10g} "
                      f"(cost {getattr(res, 'cost', 'paper')})", [
                          f"{res.method or 'refine'}: {res.iterations} iterations, "
                          f"{'converged' if res.converged else 'not converged'}"
                          f"{': ' + res.reason if res.reason else ''}; anchor pose {res.anchor}; "
                          f"backend {res.backend or '—'}; time {t:.3g} s"])


def _n_poses(res) -> int:
    """The number of poses of a planar (``poses`` (n, 3)) or 3-D (``t`` (n, 3)) result."""
    return int(res.t.shape[0] if getattr(res, "dim", 2) == 3 else res.poses.shape[0])


def refine_summary(res) -> Summary:
    """``summary()`` of a ``lago_cvx.refinement.RefineResult`` or a 3-D ``Refine3DResult``: a dict that prints as a
    small table."""
    t = res.log[-1]["time"] if res.log else float("nan")
    title = "Refinement of the full cost eq. (3)" if getattr(res, "dim", 2) == 2 else "Refinement on SE(3)"
    return Summary(title, [
        ("n_poses", "poses", _n_poses(res)), ("chi2_initial", "χ² at the start", res.chi2_initial),
        ("chi2", "χ² at the end", res.chi2), ("iterations", "iterations", res.iterations),
        ("converged", "converged", bool(res.converged)), ("reason", "reason", res.reason),
        ("method", "method", res.method), ("anchor", "anchor pose", res.anchor), ("backend", "backend", res.backend),
    ], timings={"total": t})
