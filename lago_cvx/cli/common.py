"""What every sub-command shares: exit statuses, option types, the route options, output targets,
printing (human lines or one JSON object), and the translation of library messages into CLI terms.

Exit statuses (``lago-cvx --help`` and the user guide, docs/guide.md, list them):

| status | meaning |
|---|---|
| 0 | success |
| 1 | internal error (a bug, or a solver failure) — one line, ``LAGO_CVX_DEBUG=1`` for a traceback |
| 2 | the user's input: unreadable or malformed file, unusable graph, bad option, an output that cannot be written, an estimate that is not finite |
| 3 | ``certify`` only: the estimate was computed but is not certified globally optimal |
| 4 | a resource limit reached on valid input (``--max-nodes``, ``--time-limit``) |
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys

import numpy as np

from ..errors import NonFiniteError, OptionError
from ..conventions import COSTS
from ..routes import INFORMATION_MODES, POSITIONS, REGULARIZATIONS, ROUTES

EXIT_OK, EXIT_INTERNAL, EXIT_BAD_INPUT, EXIT_NOT_CERTIFIED, EXIT_RESOURCE = 0, 1, 2, 3, 4

EXIT_TABLE = (f"exit status: {EXIT_OK} success; {EXIT_BAD_INPUT} bad input (malformed or unreadable file, unusable "
              f"graph, bad option, output that cannot be written, estimate not finite); {EXIT_NOT_CERTIFIED} "
              f"(certify) not certified; {EXIT_RESOURCE} resource limit reached on valid input (--max-nodes, "
              f"--time-limit); {EXIT_INTERNAL} internal error")

REGULARIZATION_HELP = ("2kπ regularization: tree (the paper's rounding along the spanning tree), chordal (round "
                       "every edge against the chordal relaxation), integer (weighted integer least squares of "
                       "the cycle integers, exact; small/medium graphs); default: the route's")
ROUTE_HELP = ("default (BFS tree, chordal regularization, full information, positions re-solved: chosen by "
              "measurement, see docs/results.md) or seed (exactly the paper's procedure: odometric tree, tree "
              "rounding, blkdiag(P_Δ, P_δ), phase-3 poses)")


class UsageError(OptionError):
    """A bad option value or a refused action (exit status 2)."""


# ------------------------------------------------------------------------------ option types
def tree_arg(value: str) -> str:
    v = value.replace("-", "_").lower()
    if v not in ("bfs", "odometry", "mst"):
        raise argparse.ArgumentTypeError(f"unknown spanning tree {value!r} (choose bfs, odometry or mst)")
    return v


def method_arg(value: str) -> str:
    v = value.replace("-", "_").lower()
    if v not in ("closed_form", "cvxpy"):
        raise argparse.ArgumentTypeError(f"unknown method {value!r} (choose closed-form or cvxpy)")
    return v


# The values these types accept, as written on the command line (argparse's ``choices`` would refuse the
# spellings the types also accept, e.g. closed_form); tests/test_option_matrix.py walks them.
tree_arg.choices = ("bfs", "odometry", "mst")
method_arg.choices = ("closed-form", "cvxpy")


def _int(value: str, what: str, low: int) -> int:
    try:
        v = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be an integer, got {value!r}") from None
    if v < low:
        raise argparse.ArgumentTypeError(f"{what} must be >= {low}, got {value}")
    return v


def nonneg_int(value: str) -> int:
    """An integer ≥ 0 (argparse type)."""
    return _int(value, "the value", 0)


def positive_int(value: str) -> int:
    """An integer ≥ 1 (argparse type)."""
    return _int(value, "the value", 1)


def positive_float(value: str) -> float:
    """A finite number > 0 (argparse type)."""
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {value!r}")
    return v


def nonneg_float(value: str) -> float:
    """A finite number ≥ 0 (argparse type)."""
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {value!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {value!r}")
    return v


COST_HELP = ("the cost the file's information is read for: g2o (g2o's chi2, the default for g2o files), gtsam "
             "(GTSAM's 2*error(), Logmap error) or paper (the LAGO paper's eq. (3), the default for TORO files)")
BLOCKS_HELP = "blocks: drop the information's translation-rotation cross terms on reading, as SE-Sync does"


def add_input_options(s, *, information: bool = True) -> None:
    """The reading options (``read_graph``'s keywords): ``--edge2-order`` (how ``EDGE2`` lines store their six
    information entries), ``--cost``, ``--repair-information`` and, unless the command's route options define it
    (``information=False``), ``--information {full,blocks}``."""
    s.add_argument("--edge2-order", choices=["toro", "g2o"], default=None, metavar="{toro,g2o}",
                   help="how TORO EDGE2 lines store the information: toro (Ixx Ixy Iyy Itt Ixt Iyt, the "
                        "default) or g2o (I11 I12 I13 I22 I23 I33, as some converted files do)")
    s.add_argument("--cost", choices=list(COSTS), default=None, help=COST_HELP)
    s.add_argument("--repair-information", action="store_true",
                   help="replace information matrices that are not positive definite (e.g. in files g2o saved "
                        "with 6 digits) by the nearest positive-definite matrix, counted and logged")
    if information:
        s.add_argument("--information", choices=["full", "blocks"], default=None,
                       help="full (every entry as written, the default) or " + BLOCKS_HELP)


def read_input(args, path=None):
    """Read ``path`` (default ``args.file``) with the command's input options."""
    from ..io import read_graph

    return read_graph(args.file if path is None else path, edge2_order=getattr(args, "edge2_order", None),
                      cost=getattr(args, "cost", None),
                      information="blocks" if getattr(args, "information", None) == "blocks" else "full",
                      repair=bool(getattr(args, "repair_information", False)))


def route_information(args):
    """The route's ``information`` option from ``--information`` (``blocks`` is applied on reading: None then)."""
    value = getattr(args, "information", None)
    return None if value == "blocks" else value


def add_route_options(s, *, phases: bool = False, integer: bool = True) -> None:
    """--route and the choices it makes (left unset: the route's), and the integer search's limits."""
    s.add_argument("--route", choices=list(ROUTES), default="default", help=ROUTE_HELP)
    s.add_argument("--spanning-tree", type=tree_arg, default=None,
                   help="bfs, odometry or mst (default: the route's: bfs, or odometry for --route seed)")
    s.add_argument("--regularization", choices=list(REGULARIZATIONS), default=None, help=REGULARIZATION_HELP)
    if phases:
        s.add_argument("--information", choices=[*INFORMATION_MODES, "blocks"], default=None,
                       help="full (each edge's 3×3 information in phases 2–3) or marginal (the paper's "
                            "blkdiag(P_Δ, P_δ)); default: the route's; " + BLOCKS_HELP)
        s.add_argument("--positions", choices=list(POSITIONS), default=None,
                       help="phase3 (the paper's poses) or resolve (positions re-solved exactly for the "
                            "orientations); default: the route's")
    if integer:
        g = s.add_argument_group("integer regularization limits (--regularization integer; exit 4 when reached)")
        g.add_argument("--max-nodes", type=positive_int, default=None,
                       help="node budget of the exact enumeration (default 2000000)")
        g.add_argument("--max-shift", type=nonneg_int, default=None,
                       help="search only |k − k_round| ≤ MAX_SHIFT per cycle integer")
        g.add_argument("--time-limit", type=positive_float, default=None,
                       help="seconds for the mixed-integer solver (--method cvxpy; default 60)")


def integer_search(args):
    """The ``IntegerSearch`` the limits ask for, or None (the library's defaults)."""
    kw = {k: getattr(args, k, None) for k in ("max_nodes", "max_shift", "time_limit")}
    kw = {k: v for k, v in kw.items() if v is not None}
    if not kw:
        return None
    from ..solvers import IntegerSearch

    return IntegerSearch(**kw)


def check_regularization(graph, regularization: str | None) -> None:
    """Refuse ``integer`` on graphs with more than ``MAX_INTEGER_CHORDS`` independent cycles (its cycle
    covariance is dense in their number) with a usage error instead of an internal one."""
    if regularization != "integer":
        return
    from ..graph import connected_components
    from ..regularization import MAX_INTEGER_CHORDS

    k, _ = connected_components(graph)
    n_cycles = graph.n_edges - graph.n_poses + k
    if n_cycles > MAX_INTEGER_CHORDS:
        raise UsageError(f"--regularization integer works with a dense {n_cycles} x {n_cycles} cycle covariance; "
                         f"this graph has {n_cycles} independent cycles (more than {MAX_INTEGER_CHORDS}): "
                         "use --regularization chordal")


# ----------------------------------------------------------------------------------- output
def output_target(args, *, flag: str = "-o", what: str = "the estimate") -> str | None:
    """Check ``-o`` before any work is done. Returns None (no output), ``"-"`` (standard output) or the
    path. An empty name, ``-o -`` together with ``--json`` (both on standard output), and the input file
    itself or ``args.estimate`` (also through a link, unless the command has ``--overwrite-input`` and it is given;
    the message names ``what`` is written) are refused with exit 2; so is a target
    that cannot be written (missing directory, a directory, …) — checked again when writing."""
    out = getattr(args, "output", None)
    if out is None:
        return None
    if out == "":
        raise UsageError(f"{flag}: the output file name is empty")
    if out == "-":
        if getattr(args, "json", False):
            raise UsageError(f"{flag} - writes the estimate to standard output, where --json prints too: "
                             "choose one")
        return "-"
    overridable = hasattr(args, "overwrite_input")  # the command offers --overwrite-input
    for src in (getattr(args, "file", None), getattr(args, "estimate", None)):
        if src is not None and not getattr(args, "overwrite_input", False) and _same_file(out, src):
            raise UsageError(f"refusing to overwrite the input file {src} with {what} "
                             + ("(pass --overwrite-input to allow it)" if overridable else "(name another file)"))
    _check_writable(out, flag)
    return out


def _same_file(a: str, b: str) -> bool:
    """True when both paths name one existing file (through symbolic or hard links): ``io.same_file``."""
    from ..io.output import same_file

    return same_file(a, b)


def _check_writable(out: str, flag: str) -> None:
    """Fail early, before the work, for targets that can never be written: a directory, a missing
    parent directory, a parent that is not a directory. (Writing reports the rest: permissions, a full
    device.) A symbolic link is judged by its target."""
    path = os.path.realpath(out)
    if os.path.isdir(path):
        raise UsageError(f"{flag} {out}: is a directory")
    parent = os.path.dirname(path) or "."
    if not os.path.exists(parent):
        raise UsageError(f"{flag} {out}: directory {os.path.dirname(out) or '.'} does not exist")
    if not os.path.isdir(parent):
        raise UsageError(f"{flag} {out}: {os.path.dirname(out)} is not a directory")


def write_estimate(target: str, graph, poses) -> None:
    """Write ``poses`` (n, 3) with the graph's edges as g2o to ``target`` (a path or ``"-"``)."""
    from ..io import write_graph

    write_graph(target, graph, poses)


def write_bytes(target: str, data: bytes) -> None:
    """Write ``data`` to ``target`` with the output rules of ``lago_cvx.io`` (atomic replace of a regular
    file, through links, streamed to special files); errors exit 2 naming ``target``."""
    from ..io import write_bytes as _write

    _write(target, data)


def check_finite(chi2_value: float, poses, *, what: str = "estimate") -> None:
    """Exit 2 (``NonFiniteError``) when χ² or the poses are not finite: the data overflow double
    precision. Called before anything is written."""
    bad_poses = poses is not None and not np.isfinite(np.asarray(poses)).all()
    if bad_poses or not math.isfinite(chi2_value):
        part = "its poses are" if bad_poses else f"its χ² is {chi2_value}"
        raise NonFiniteError(f"the {what} is not finite: {part} (the measurements or information overflow "
                             "double precision); nothing was written")


def sigma_keywords(sigma_xy, sigma_theta, *, names: tuple[str, str] = ("sigma_xy", "sigma_theta")) -> dict:
    """The noise keywords of a synthetic world that ``generate`` was given (``--sigma-xy``, ``--sigma-theta``;
    None keeps the world's default), under the world's own ``names`` (translation, rotation)."""
    return {name: value for name, value in zip(names, (sigma_xy, sigma_theta)) if value is not None}


def abs_tol_hint(cert, args) -> str:
    """A hint at ``--abs-tol`` when the certificate proved S ⪰ −ηI but the bound is too weak by far (relative gap
    above 0.1: the floor's share of the gap dwarfs f, as on a graph with almost no noise) and no ``--abs-tol`` was
    given; "" otherwise."""
    if args.abs_tol or "bound too weak" not in cert.verdict or not cert.relative_suboptimality_bound > 0.1:
        return ""
    return (f"f = {cert.cost:.3g} is too small for a relative test (a graph with almost no noise): --abs-tol ABS "
            "certifies it when the proven gap f − f* ≤ ABS")


# ---------------------------------------------------------------------------------- printing
def check_fields(report: dict, robust) -> dict:
    """``--check``'s JSON fields: the largest relative differences and cvxpy's timings; with ``--robust`` they are
    those of LAGO on the accepted edges (``check_edges``)."""
    return {"max_rel_diff": report["max_rel_diff"], "cvxpy_timings": report["cvxpy_timings"],
            **({"check_edges": "accepted"} if robust else {})}


def check_line(report: dict, robust) -> str:
    """``--check``'s line of text (with ``--robust``: on how many accepted edges)."""
    return ("  cvxpy vs closed form" + (f" (LAGO on the {report['accepted_edges']} accepted edges)" if robust else "")
            + ", max relative difference: " + ", ".join(f"{k} {v:.2e}" for k, v in report["max_rel_diff"].items()))


def graph_lines(graph, components: int, cyclomatic_number: int) -> list[str]:
    """``info``'s human lines on the graph's size, planar and 3-D alike: poses, edges, odometric edges, loop
    closures, connected components and the cyclomatic number l = m − n + components."""
    return [f"poses             {graph.n_poses}" + ("" if graph.initial is not None else "  (no initial guess)"),
            f"edges             {graph.n_edges}",
            f"odometric edges   {graph.n_odometric}  (consecutive ids)",
            f"loop closures     {graph.n_loop_closures}",
            f"components        {components}",
            f"cyclomatic number {cyclomatic_number}  (l = m - n + components)"]


def strict_json(obj):
    """Non-finite floats become null: the output must be strict JSON (RFC 8259 has no NaN/Infinity)."""
    if isinstance(obj, dict):
        return {k: strict_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def emit(args, payload: dict, lines: list[str], *, stdout_taken: bool = False) -> None:
    """Print one JSON object (``--json``) or the human lines; when the estimate itself goes to standard
    output (``-o -``), the human lines go to standard error."""
    try:
        if getattr(args, "json", False):
            print(json.dumps(strict_json(payload), allow_nan=False))
        else:
            print("\n".join(lines), file=sys.stderr if stdout_taken else sys.stdout)
    except BrokenPipeError:  # the reader left: main ends quietly
        raise
    except OSError as exc:  # e.g. a full disk behind standard output: an output that cannot be written (exit 2)
        raise stdout_error(exc) from None


def stdout_error(exc: OSError):
    """The ``OutputError`` of a failed write to standard output (path "-")."""
    from ..errors import OutputError

    return OutputError(f"cannot write standard output: {exc.strerror or exc}", path="-", errno=exc.errno)


_KEYWORD_VALUE = re.compile(r'\b([a-z][a-z_]*)="([\w.-]+)"(?: or "([\w.-]+)")?')
_BARE_OPTIONS = ("max_nodes", "max_shift", "time_limit", "max_iterations")
#: Library phrases with no keyword=value form, and their CLI wording.
_PHRASES = ((re.compile(r'\bthe solver "enumerate"'), "--method closed-form"),)


def speak_cli(message: str) -> str:
    """Library messages name Python keywords (``spanning_tree="bfs"``, ``max_nodes``); on the command line
    they become options (``--spanning-tree bfs``, ``--max-nodes``)."""
    def option(m):
        flag = "--" + m.group(1).replace("_", "-")
        return f"{flag} {m.group(2)}" + (f" or {flag} {m.group(3)}" if m.group(3) else "")

    message = _KEYWORD_VALUE.sub(option, message)
    for pattern, cli in _PHRASES:
        message = pattern.sub(cli, message)
    for name in _BARE_OPTIONS:
        message = re.sub(rf"\b{name}\b", "--" + name.replace("_", "-"), message)
    return message


def debug_enabled() -> bool:
    return bool(os.environ.get("LAGO_CVX_DEBUG"))


# ---------------------------------------------------------------------------------- progress
class ProgressBar:
    """Draws the library's progress reports (``progress(stage, fraction)``, ``lago_cvx.progress``) as one
    self-overwriting line on standard error: ``  phase 3: factorization  [########            ]  42 %``.
    A stage's line is finished (newline) when it reports 1.0."""

    WIDTH = 24

    def __init__(self, stream=None):
        self.stream = stream or sys.stderr
        self.active = None

    def __call__(self, stage: str, fraction: float) -> None:
        fraction = min(max(float(fraction), 0.0), 1.0)
        filled = int(round(fraction * self.WIDTH))
        self.stream.write(f"\r  {stage:<40.40} [{'#' * filled}{' ' * (self.WIDTH - filled)}] {100 * fraction:3.0f} %")
        self.active = stage
        if fraction >= 1.0:
            self.stream.write("\n")
            self.active = None
        self.stream.flush()


def progress_callback(args):
    """A ``ProgressBar`` when standard error is a terminal and the output is for humans (no ``--json``,
    no ``LAGO_CVX_NO_PROGRESS``); otherwise None (the library then only logs, at INFO, with ``-v``)."""
    if getattr(args, "json", False) or os.environ.get("LAGO_CVX_NO_PROGRESS"):
        return None
    try:
        tty = sys.stderr.isatty()
    except (AttributeError, ValueError):
        tty = False
    return ProgressBar() if tty else None


def robust_payload(args, graph, robust) -> dict:
    """The JSON keys of ``certify --robust``: the input's edge count, the rejected edges (file order), and that the
    certificate is about the accepted edges (``robust`` a ``RobustResult`` or ``Robust3DResult`` of ``graph``)."""
    return {"robust": args.robust, "certified_edges": "accepted", "n_edges_input": graph.n_edges,
            "n_edges": robust.graph.n_edges, "n_rejected": int(robust.rejected_edges.size),
            "rejected_edges": robust.rejected_edges.tolist(), "robust_iterations": robust.iterations,
            "robust_threshold": robust.settings.c2_for(graph.dim)}
