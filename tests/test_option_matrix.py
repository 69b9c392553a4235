"""Every option with every other (issue 30): the combinations of the CLI's options, tested by construction.

The option space is read from the parser ``lago_cvx.cli.build_parser`` builds — its sub-commands and their
actions' flags, ``choices`` (also a type's ``choices``), counts and switches — so a new option joins the
matrix without anyone adding it here (an option whose values cannot be derived fails
``test_parser_space_is_complete`` and asks for them). Every command that reads a graph is run in process
(``main([...])``) on three small graphs written to a temporary folder: one with unsorted, offset ids, one
with a broken odometric chain, one TORO file.

The full cross product is far too big; ``pairwise`` is a deterministic greedy covering design (every pair of
values of two options appears together in at least one run), plus every anchor form × ``--refine`` ×
``--check``. Every run must end in exit 0 or a documented 2, 3 (``certify``), 4 with one ``lago-cvx: error:``
line in CLI words on standard error — never 1, never a traceback; where poses are written the given anchors
hold to 1e-9 (also after ``--refine``); ``--check`` agrees to 1e-6. The library's ``lago``,
``compare_methods`` and ``refine`` with ``anchors=`` are held to the same, and hypothesis draws random
argument lists from the parser's space too.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import os
import random
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lago_cvx.cli import build_parser, main
from lago_cvx.cli.common import method_arg, tree_arg
from lago_cvx.errors import LagoError, OptionError
from lago_cvx.io import read_graph, write_graph
from lago_cvx.posegraph import wrap_angle
from lago_cvx.synthetic import circle_world, manhattan_world

ANCHOR_TOL = 1e-9  # the anchored coordinates are put in exactly; what is left is the text round trip
CHECK_TOL = 1e-6  # cvxpy (Clarabel, default accuracy) against the closed form

# -------------------------------------------------------------------------------------------- graphs


def _rewrite(path: Path, lines: list[str]) -> None:
    path.write_text("\n".join(lines) + "\n")


def write_graphs(folder: Path) -> dict[str, Path]:
    """Three small graphs (≤ 50 poses): ``unsorted`` (ids 100…139, vertex and edge lines shuffled),
    ``broken`` (id 25 missing: the chain of consecutive ids is broken, the graph still connected) and
    ``toro`` (a two-lap circle as TORO ``VERTEX2``/``EDGE2`` lines)."""
    out = {}
    p = folder / "unsorted.g2o"
    write_graph(p, manhattan_world(40, seed=3).graph)
    rnd = random.Random(0)
    lines = []
    for ln in p.read_text().splitlines():
        t = ln.split()
        k = 2 if t[0].startswith("VERTEX") else 3
        t[1:k] = [str(int(v) + 100) for v in t[1:k]]
        lines.append(" ".join(t))
    rnd.shuffle(lines)
    _rewrite(p, lines)
    out["unsorted"] = p
    p = folder / "broken.g2o"
    write_graph(p, manhattan_world(50, seed=5).graph)
    lines = []
    for ln in p.read_text().splitlines():
        t = ln.split()
        k = 2 if t[0].startswith("VERTEX") else 3
        t[1:k] = [str(int(v) + (int(v) >= 25)) for v in t[1:k]]
        lines.append(" ".join(t))
    _rewrite(p, lines)
    out["broken"] = p
    p = folder / "circle.graph"
    write_graph(p, circle_world(24, laps=2, seed=1).graph, format="toro")
    out["toro"] = p
    return out


@pytest.fixture(scope="module")
def graphs(tmp_path_factory) -> dict[str, Path]:
    return write_graphs(tmp_path_factory.mktemp("graphs"))


def anchor_forms(ids) -> dict[str, list[str]]:
    """The ``--anchor`` forms on a graph with pose ``ids``: none, a bare id, one ``ID:X,Y,THETA``, several,
    and the two partial ones (orientation only, position only)."""
    a, b = int(ids[len(ids) // 3]), int(ids[2 * len(ids) // 3])
    return {"none": [], "bare": ["--anchor", str(a)], "full": ["--anchor", f"{a}:1.5,-2,0.7"],
            "several": ["--anchor", f"{a}:1.5,-2,0.7", "--anchor", f"{b}:4,3,-2.9"],
            "partial-theta": ["--anchor", f"{b}:,,2.5"], "partial-position": ["--anchor", f"{b}:3,1,"]}


# ------------------------------------------------------------------------------------ the option space
#: Values of typed options without choices: by destination first, then by type. A new option of a known
#: type joins the matrix with these; an unknown type fails ``test_parser_space_is_complete``.
_BY_DEST = {"max_nodes": ["1", "100000"], "max_shift": ["0", "2"], "time_limit": ["30"], "max_iterations": ["0", "5"],
            "tol": ["1e-4"], "every": ["7"], "sigma": ["2"], "size": ["3"], "dpi": ["20"], "title": ["a title"]}
_BY_TYPE = {"positive_int": ["3"], "nonneg_int": ["0", "3"], "positive_float": ["0.5"], "nonneg_float": ["0"],
            "confidence_arg": ["0.999"]}
_SKIPPED = ("help", "version")


class Unknown(Exception):
    """An option whose values this test cannot derive."""


def _flag(action) -> str:
    longs = [s for s in action.option_strings if s.startswith("--")]
    return (longs or action.option_strings)[0]


def option_values(command: str, action, ctx: dict) -> list[list[str]] | None:
    """The values of one parser action as argument lists ([] = left out); None for actions not varied
    (help, version, the graph file itself). ``ctx``: ``graph`` (path), ``out`` (folder), ``ids``."""
    import argparse

    if isinstance(action, (argparse._HelpAction, argparse._VersionAction)) or action.dest in _SKIPPED:
        return None
    if not action.option_strings:  # positionals
        if action.dest == "file":
            return None
        if action.dest == "estimate":  # plot: a file whose vertices are the estimate
            return [[], [str(ctx["graph"])]]
        raise Unknown(f"{command}: positional {action.dest!r}")
    flag = _flag(action)
    absent = [] if action.required else [[]]
    if isinstance(action, (argparse._StoreTrueAction, argparse._CountAction)):
        return [[], [flag]]
    if action.dest == "anchor":
        return list(anchor_forms(ctx["ids"]).values())
    if action.dest == "output":
        ext = ".svg" if command == "plot" else ".g2o"
        return absent + [[flag, str(ctx["out"] / f"out{ext}")], [flag, "-"]]
    choices = action.choices if action.choices is not None else getattr(action.type, "choices", None)
    if choices is not None:
        return absent + [[flag, str(c)] for c in choices]
    samples = _BY_DEST.get(action.dest) or _BY_TYPE.get(getattr(action.type, "__name__", None))
    if samples is None and action.type is None and action.nargs is None:
        samples = ["x"]
    if samples is None:
        raise Unknown(f"{command} {flag}: type {getattr(action.type, '__name__', action.type)!r}")
    return absent + [[flag, v] for v in samples]


def parser_space(ctx: dict) -> dict[str, list[tuple[str, list[list[str]]]]]:
    """{command: [(option name, values)]} for every sub-command that reads a graph (a positional
    ``file``), from the parser itself."""
    import argparse

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    space = {}
    for name, cmd in sub.choices.items():
        if not any(a.dest == "file" and not a.option_strings for a in cmd._actions):
            continue
        params = []
        for action in sorted(cmd._actions, key=lambda a: bool(a.option_strings)):  # positionals first
            values = option_values(name, action, ctx)
            if values is not None:
                params.append((action.dest, values))
        space[name] = params
    return space


def _gain(row: list, p: int, v: int, uncovered: set) -> int:
    """How many uncovered pairs value ``v`` of parameter ``p`` covers with the values set in ``row``."""
    return sum(((q, row[q], p, v) if q < p else (p, v, q, row[q])) in uncovered
               for q in range(len(row)) if row[q] is not None)


def pairwise(domains: list[int]) -> list[tuple[int, ...]]:
    """A covering array of strength 2: rows of value indices such that for every two parameters i < j
    and values a < domains[i], b < domains[j] some row has (a, b) at (i, j). Greedy and deterministic:
    each row starts from the first pair not yet covered and gives every other parameter, in order, the
    value that covers most uncovered pairs with the values already set (ties: the smallest value)."""
    k = len(domains)
    uncovered = {(i, a, j, b) for i, j in itertools.combinations(range(k), 2)
                 for a in range(domains[i]) for b in range(domains[j])}
    rows = []
    if k == 1:
        return [(a,) for a in range(domains[0])]
    while uncovered:
        i, a, j, b = min(uncovered)
        row = [None] * k
        row[i], row[j] = a, b
        for p in range(k):
            if row[p] is None:
                row[p] = max(range(domains[p]), key=lambda v, p=p, row=row: (_gain(row, p, v, uncovered), -v))
        rows.append(tuple(row))
        uncovered -= {(p, row[p], q, row[q]) for p, q in itertools.combinations(range(k), 2)}
    return rows


# ----------------------------------------------------------------------------------------- running
def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """``main(argv)`` in process: (exit status, standard output, standard error)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue(), err.getvalue()


_LIBRARY_WORDS = re.compile(r'\b[a-z]+_[a-z_]+\s*=|solver "enumerate"|\bmax_nodes\b|\bmax_shift\b|\btime_limit\b'
                            r'|\bspanning_tree\b|\bintegration_search\b|\binteger_search\b')


def _expected_anchors(argv: list[str]) -> dict[int, tuple]:
    """{id: (x, y, θ) with None unknown} the run's ``--anchor`` values promise (a bare id: the origin)."""
    specs = [argv[k + 1] for k, a in enumerate(argv) if a == "--anchor"]
    if len(specs) == 1 and ":" not in specs[0]:
        return {int(specs[0]): (0.0, 0.0, 0.0)}
    out = {}
    for s in specs:
        pid, vals = s.split(":")
        out[int(pid)] = tuple(None if v == "" else float(v) for v in vals.split(","))
    return out


def anchor_violation(ids, poses, anchors: dict) -> float:
    """Largest violation of ``anchors`` by ``poses`` (n, 3) with pose ``ids``; θ modulo 2π."""
    worst = 0.0
    index = {int(i): k for k, i in enumerate(ids)}
    for pid, (x, y, th) in anchors.items():
        p = poses[index[pid]]
        if x is not None:
            worst = max(worst, abs(p[0] - x), abs(p[1] - y))
        if th is not None:
            worst = max(worst, abs(float(wrap_angle(p[2] - th))))
    return worst


def check_run(argv: list[str], code: int, out: str, err: str, tmp: Path) -> list[str]:
    """The problems of one run (empty: it behaved): exit status, standard error's wording, anchors held in
    the poses written, --check's agreement, --json's one object."""
    cmd = argv[0]
    why = []
    if "Traceback" in err or "internal error" in err:
        why.append("traceback or internal error")
    if code not in (0, 2, 3, 4) or (code == 3 and cmd != "certify"):
        why.append(f"exit status {code}")
    if code in (2, 4):
        lines = err.strip().splitlines()
        errors = [ln for ln in lines if ln.startswith("lago-cvx: error: ")]
        if len(errors) != 1 or lines[-1] != errors[0]:
            why.append(f"standard error is not one error line: {err!r}")
        elif _LIBRARY_WORDS.search(errors[0]):
            why.append(f"library words in {errors[0]!r}")
        if any(not ln.startswith("lago-cvx: ") for ln in lines):
            why.append(f"a line not in CLI form: {err!r}")
    if code not in (0, 3):
        return why
    json_out = "--json" in argv
    if json_out:
        try:
            payload = json.loads(out)
        except ValueError:
            return why + [f"--json printed {out[:200]!r}"]
    if cmd == "solve" and "--check" in argv:
        if json_out:
            diffs = payload["max_rel_diff"].values()
        else:
            line = next(ln for ln in (out + err).splitlines() if "max relative difference" in ln)
            diffs = [float(v) for v in re.findall(r"\s([0-9.]+e[-+]\d+)", line)]
        if not diffs or max(diffs) > CHECK_TOL:
            why.append(f"--check: cvxpy and closed form differ by {max(diffs, default=None)}")
    flags = [a for a in ("-o", "--output") if a in argv]
    if cmd == "solve" and flags:
        target = argv[argv.index(flags[0]) + 1]
        text = out if target == "-" else Path(target).read_text()
        written = tmp / "written.g2o"
        written.write_text(text)
        g = read_graph(written)
        viol = anchor_violation(g.ids, g.initial, _expected_anchors(argv))
        if viol > ANCHOR_TOL:
            why.append(f"anchors violated by {viol:.3g} in the poses written")
    return why


#: What the TORO graph adds is its format (--edge2-order); the slowest command (plot, ~0.4 s a run) and the
#: anchor block run on the other two graphs only, to keep the matrix within a minute.
_FORMAT_ONLY = "toro"


def matrix_runs(graphs: dict[str, Path], out: Path) -> list[list[str]]:
    """The argument lists of the matrix: per graph and command the pairwise rows, plus every anchor form ×
    --refine × --check of ``solve`` (written to a file, so that the anchors are checked)."""
    runs = []
    for gname, path in graphs.items():
        ids = read_graph(path).ids
        ctx = {"graph": path, "out": out, "ids": ids}
        for cmd, params in parser_space(ctx).items():
            if gname == _FORMAT_ONLY and cmd == "plot":
                continue
            for row in pairwise([len(v) for _, v in params]):
                argv = [cmd, str(path)]
                for (_, values), k in zip(params, row):
                    argv += values[k]
                runs.append(argv)
        if gname == _FORMAT_ONLY:
            continue
        for form in anchor_forms(ids).values():
            for extra in itertools.product([[], ["--refine"]], [[], ["--check"]]):
                runs.append(["solve", str(path), *form, *extra[0], *extra[1], "-o", str(out / "anchored.g2o")])
    return runs


# ------------------------------------------------------------------------------------------- tests
def test_pairwise_covers_every_pair_deterministically():
    domains = [3, 4, 2, 6, 2, 2, 3]
    rows = pairwise(domains)
    assert rows == pairwise(domains)
    for i, j in itertools.combinations(range(len(domains)), 2):
        seen = {(r[i], r[j]) for r in rows}
        assert seen == set(itertools.product(range(domains[i]), range(domains[j])))
    full = int(np.prod(domains))
    assert max(a * b for a, b in itertools.combinations(domains, 2)) <= len(rows) < full / 10


def test_parser_space_is_complete(tmp_path, graphs):
    """Every option of every graph-reading command has values (none is unknown), and the ones the issue
    names are among them."""
    ids = read_graph(graphs["unsorted"]).ids
    space = parser_space({"graph": graphs["unsorted"], "out": tmp_path, "ids": ids})
    assert {"info", "solve", "certify", "plot"} <= set(space)
    solve = dict(space["solve"])
    for dest in ("route", "spanning_tree", "regularization", "information", "positions", "method", "anchor",
                 "check", "refine", "output", "json"):
        assert dest in solve, dest
    assert len(solve["anchor"]) == 6 and len(solve["output"]) == 3
    assert solve["spanning_tree"][1:] == [["--spanning-tree", v] for v in tree_arg.choices]
    assert solve["method"][1:] == [["--method", v] for v in method_arg.choices]


def test_option_matrix_cli(tmp_path, graphs, record_property):
    """The whole matrix: pairwise rows of every graph-reading command on three graphs (plot on two), plus the
    anchor forms × --refine × --check on two. Prints the number of runs and their time (pytest -s)."""
    runs = matrix_runs(graphs, tmp_path)
    t0 = time.perf_counter()
    failures, codes = [], {}
    for argv in runs:
        code, out, err = run_cli(argv)
        codes[code] = codes.get(code, 0) + 1
        why = check_run(argv, code, out, err, tmp_path)
        if why:
            failures.append(f"lago-cvx {' '.join(argv)}: {'; '.join(why)}")
    seconds = time.perf_counter() - t0
    record_property("option_matrix", {"runs": len(runs), "seconds": round(seconds, 1), "exit_codes": codes})
    print(f"\noption matrix: {len(runs)} runs in {seconds:.1f} s, exit statuses {codes}")
    assert not failures, "\n".join(failures[:20])
    assert codes.get(0, 0) > len(runs) / 2  # most combinations work: the matrix is not all refusals


@pytest.mark.parametrize("graph", ["unsorted", "broken"])
def test_library_anchors_hold(graph, graphs):
    """``lago``, ``compare_methods`` and ``refine`` with ``anchors=`` over pairwise combinations of lago's
    keywords: anchors hold to 1e-9 (also after refine), compare_methods agrees to 1e-6, and refusals
    are ``LagoError``s — never a TypeError."""
    from lago_cvx.pipeline import compare_methods, lago
    from lago_cvx.refinement import refine
    from lago_cvx.solvers import IntegerSearch

    g = read_graph(graphs[graph])
    forms = {name: _expected_anchors(["x", *form]) if form else {} for name, form in anchor_forms(g.ids).items()}
    forms.pop("bare")  # a bare id is lago's anchor=, not anchors=
    keywords = {"route": ["default", "seed"], "spanning_tree": [None, "bfs", "odometry", "mst"],
                "regularization": [None, "tree", "chordal", "integer"], "information": [None, "full", "marginal"],
                "positions": [None, "phase3", "resolve"], "method": ["closed_form", "cvxpy"],
                "integer_search": [None, IntegerSearch(max_nodes=100_000)], "anchors": list(forms.values())}
    names = list(keywords)
    failures, rows, solved = [], pairwise([len(keywords[k]) for k in names]), 0
    for row in rows:
        kw = {k: keywords[k][v] for k, v in zip(names, row)}
        anchors = kw["anchors"]
        try:
            res = lago(g, **kw)
            ref = refine(g, res.poses, anchors=anchors)
            kw.pop("method")
            _, report = compare_methods(g, **kw)
        except LagoError:  # e.g. the seed route's odometric tree on the broken chain
            continue
        except Exception as exc:  # noqa: BLE001 - collected, reported below
            failures.append(f"{kw}: {type(exc).__name__}: {exc}")
            continue
        solved += 1
        for what, poses in (("lago", res.poses), ("refine", ref.poses)):
            if anchor_violation(g.ids, poses, anchors) > ANCHOR_TOL:
                failures.append(f"{kw}: anchors violated after {what}")
        if max(report["max_rel_diff"].values()) > CHECK_TOL:
            failures.append(f"{kw}: compare_methods differs by {report['max_rel_diff']}")
        if not ref.chi2 <= ref.chi2_initial:
            failures.append(f"{kw}: refine raised χ²")
    assert not failures, "\n".join(failures)
    assert solved >= len(rows) / 2, f"only {solved} of {len(rows)} combinations solved"  # not all refusals


def test_compare_methods_honours_the_integer_limits():
    """The option that crashed ``--anchor … --check`` (issue 30) is honoured: the node budget of the
    integer search is reached with anchors as without."""
    from lago_cvx.errors import SearchLimitError
    from lago_cvx.pipeline import compare_methods
    from lago_cvx.solvers import IntegerSearch
    from lago_cvx.variants import anchored_lago, compare_anchored_methods

    g = manhattan_world(120, seed=2, sigma_theta=0.2).graph
    tight = IntegerSearch(max_nodes=1)
    for anchors in (None, {0: (0.0, 0.0, 0.0)}):
        with pytest.raises(SearchLimitError):
            compare_methods(g, anchors=anchors, regularization="integer", integer_search=tight)
    with pytest.raises(SearchLimitError):
        anchored_lago(g, anchors={}, regularization="integer", integer_search=tight)
    with pytest.raises(OptionError, match="method"):
        compare_anchored_methods(g, anchors={}, method="cvxpy")
    with pytest.raises(OptionError, match="method"):
        compare_methods(g, method="cvxpy")


def test_lago_with_anchors_honours_the_integer_limits():
    from lago_cvx.errors import SearchLimitError
    from lago_cvx.pipeline import lago
    from lago_cvx.solvers import IntegerSearch

    g = manhattan_world(120, seed=2, sigma_theta=0.2).graph
    with pytest.raises(SearchLimitError):
        lago(g, anchors={0: (0.0, 0.0, 0.0)}, regularization="integer", integer_search=IntegerSearch(max_nodes=1))


def test_refine_holds_full_and_partial_anchors():
    """``refine(anchors=)``: the known coordinates take the given values (θ modulo 2π) and stay there; the
    gauge the anchors leave open is held at the reference pose; the unknown coordinates move, and χ²
    matches the unanchored refinement where the anchors add no information (one pose's gauge)."""
    from lago_cvx.pipeline import lago
    from lago_cvx.refinement import refine

    g = manhattan_world(60, seed=4).graph
    start = lago(g).poses
    free = refine(g, start)
    cases = {"full": {7: (1.0, 2.0, 0.3)}, "theta": {7: (None, None, 0.3)}, "position": {7: (1.0, 2.0, None)},
             "position and theta": {7: (1.0, 2.0, None), 30: (float("nan"), float("nan"), 1.0)},
             "two positions": {7: (1.0, 2.0, None), 30: (5.0, -1.0, None)},
             "several": {7: (1.0, 2.0, 0.3), 30: (5.0, -1.0, float("nan"))}}
    for name, anchors in cases.items():
        ref = refine(g, start, anchors=anchors)
        assert anchor_violation(g.ids, ref.poses, anchors) <= ANCHOR_TOL, name
        assert ref.converged, (name, ref.reason)
        gauge_only = name in ("full", "theta", "position", "position and theta")
        if gauge_only:  # three coordinates that only fix the frame: the same optimum, moved rigidly
            assert ref.chi2 == pytest.approx(free.chi2, rel=1e-8), name
        else:  # more than the frame: the optimum can only rise
            assert ref.chi2 > free.chi2 * (1 + 1e-6), name
    held = refine(g, start, anchors={7: (None, None, 0.3)}).held
    assert held[7].all() and held.sum() == 3  # θ_7 known, and the reference's (pose 7's) position held
    assert refine(g, start, anchors={7: (1.0, 2.0, None)}).held.sum() == 3  # x_7, y_7 and the reference's θ
    assert refine(g, start, anchors={7: (1.0, 2.0, None), 30: (5.0, -1.0, None)}).held.sum() == 4  # no gauge
    with pytest.raises(OptionError):
        refine(g, start, anchors={7: (1.0, None, None)})


def test_solve_refine_keeps_anchors(tmp_path):
    """The issue's case: ``solve --anchor A --anchor B --refine -o`` writes poses that keep A and B."""
    p = tmp_path / "m.g2o"
    write_graph(p, manhattan_world(60, seed=6).graph)
    out = tmp_path / "out.g2o"
    argv = ["solve", str(p), "--anchor", "0:0,0,0", "--anchor", "40:20,24,-2.6", "--refine", "-o", str(out)]
    code, _, err = run_cli(argv)
    assert code == 0, err
    written = read_graph(out)
    assert anchor_violation(written.ids, written.initial, _expected_anchors(argv)) <= ANCHOR_TOL


def test_missing_scip_is_said_in_cli_words(tmp_path, monkeypatch):
    """Without SCIP, ``--regularization integer --method cvxpy`` names the CLI's way out (--method
    closed-form), not the library's solver keyword."""
    p = tmp_path / "m.g2o"
    write_graph(p, manhattan_world(40, seed=1).graph)
    monkeypatch.setitem(sys.modules, "pyscipopt", None)  # import pyscipopt → ImportError
    code, _, err = run_cli(["solve", str(p), "--regularization", "integer", "--method", "cvxpy"])
    assert code == 2
    assert err.startswith("lago-cvx: error: ") and err.count("\n") == 1
    assert "--method closed-form" in err and "enumerate\"" not in err


_CLOSED_STDOUT = [["solve", "{g}", "-o", "-"], ["solve", "{g}"], ["solve", "{g}", "--json"], ["info", "{g}"],
                  ["info", "{g}", "--json"], ["generate", "--poses", "30", "-o", "-", "--truth", "{t}"],
                  ["datasets", "list", "--json"]]


@pytest.mark.parametrize("argv", _CLOSED_STDOUT, ids=lambda a: " ".join(a).replace("{g}", "F"))
def test_closed_standard_output_ends_quietly(tmp_path, argv):
    """A standard output whose reader has gone (a real pipe, read end closed: EPIPE at the first write)
    ends the command quietly: nothing on standard error, exit 0 (``cat`` exits 141 by SIGPIPE)."""
    p = tmp_path / "m.g2o"
    write_graph(p, manhattan_world(300, seed=1).graph)
    argv = [a.format(g=p, t=tmp_path / "t.g2o") for a in argv]
    r, w = os.pipe()
    os.close(r)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    try:
        proc = subprocess.run([sys.executable, "-m", "lago_cvx", *argv], stdout=w, stderr=subprocess.PIPE,
                              env=env, timeout=300, check=False)
    finally:
        os.close(w)
    assert proc.stderr == b"" and proc.returncode in (0, 141), (proc.returncode, proc.stderr)


def test_no_standard_output_at_all(tmp_path, monkeypatch):
    """Started without a standard output (``>&-``: ``sys.stdout`` is None): ``info`` has nothing to say
    it to and ends 0; ``solve -o -`` is refused in one line (exit 2) — never an internal error."""
    p = tmp_path / "m.g2o"
    write_graph(p, manhattan_world(30, seed=1).graph)
    for argv, status in ((["info", str(p)], 0), (["solve", str(p), "-o", "-"], 2)):
        err = io.StringIO()
        monkeypatch.setattr(sys, "stdout", None)
        with contextlib.redirect_stderr(err):
            code = main(argv)
        monkeypatch.undo()
        assert code == status and "internal error" not in err.getvalue(), (argv, code, err.getvalue())


def test_datasets_names_resolve(monkeypatch):
    """``datasets path NAME``: a unique basename or stem names its file; an ambiguous or unknown name is
    refused with the candidates."""
    from lago_cvx import datasets as D

    assert D.resolve_name("CSAIL") == "se-sync/CSAIL.g2o"
    assert D.resolve_name("CSAIL.g2o") == "se-sync/CSAIL.g2o"
    assert D.resolve_name("csail_p_toro") == "carlone/CSAIL_P_toro.graph"
    assert D.resolve_name("se-sync/MIT.g2o") == "se-sync/MIT.g2o"
    with pytest.raises(D.DatasetNotFound, match="CSAIL_P_toro"):
        D.resolve_name("CSAIL_P")
    monkeypatch.setattr(D, "DATASET_FILES", D.DATASET_FILES + ("other/CSAIL.graph",))
    with pytest.raises(D.DatasetNotFound, match="ambiguous.*se-sync/CSAIL.g2o.*other/CSAIL.graph"):
        D.resolve_name("CSAIL")
    monkeypatch.undo()
    code, _, err = run_cli(["datasets", "path", "nonesuch"])
    assert code == 2 and err.startswith("lago-cvx: error: unknown dataset 'nonesuch'") and err.count("\n") == 1


@st.composite
def _argv(draw, graphs: dict, out: Path):
    gname = draw(st.sampled_from(sorted(graphs)))
    path = graphs[gname]
    ids = read_graph(path).ids
    space = parser_space({"graph": path, "out": out, "ids": ids})
    cmd = draw(st.sampled_from(sorted(space)))
    argv = [cmd, str(path)]
    for _, values in space[cmd]:
        argv += draw(st.sampled_from(values))
    return argv


def test_random_argument_lists_from_the_parser(tmp_path_factory):
    """Hypothesis draws a graph, a command and a value (or none) for each of its options from the parser's
    space; every run must behave as in the matrix."""
    folder = tmp_path_factory.mktemp("hypothesis")
    graphs = write_graphs(folder)

    @settings(max_examples=25, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(_argv(graphs, folder))
    def run(argv):
        code, out, err = run_cli(argv)
        why = check_run(argv, code, out, err, folder)
        assert not why, f"lago-cvx {' '.join(argv)}: {'; '.join(why)}"

    run()
