"""The course in lectures/ holds together.

* each lecture's .py/.ipynb pair is in sync, and the committed notebook holds rendered outputs — at
  least one figure, no error (``python lectures/render.py`` stores them);
* each lecture executes top to bottom with nbclient (working directory lectures/, figures written to a
  temporary folder so the tracked ones stay as they are);
* each lecture has two or three exercises, each with a hint, a stub cell (a signature and a call of its check in
  ``lago_cvx.exercises``) and a "Solution and Discussion" cell collapsed in Jupyter and hidden in the site, whose
  stored output shows that its check accepts it; at least three lectures set an exercise mid-lecture;
* each lecture has a notation table and a summary;
* lectures 01–06 carry one running example and INTEL; a world of a section's own says why;
* no ``matplotlib.use`` and no internal wording in the course's prose;
* lectures/CONCORDANCE.md covers every item of the paper (../shared/SEED.md beside the project) and
  every row points at a real section, importable package names and existing tests;
* the course site builds from the stored outputs without a warning;
* running a lecture as a script leaves no tracked change and no untracked file.

Real-data cells read ../shared/datasets through ``lago_cvx.datasets`` and say so when it is absent.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import io
import os
import re
import shutil
import subprocess
import sys
import time
import tokenize
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
LECTURES = ROOT / "lectures"
SOURCES = sorted(LECTURES.glob("[0-9][0-9]*_*.py"))
IDS = [s.stem for s in SOURCES]
SEED_MD = ROOT.parent / "shared" / "SEED.md"
CONCORDANCE = LECTURES / "CONCORDANCE.md"

#: A lecture may take 60 s here; the tests fail only far beyond that (a sweep left on, a hang).
LECTURE_SECONDS_LIMIT = 180
#: The lecture that the script-run test executes: the quickest.
SCRIPT_LECTURE = "01"

SECTION = re.compile(r"^## (\d+)\. \S")
EXERCISE = re.compile(r"^## Exercise (\d+) — \S")


def _jupytext():
    return pytest.importorskip("jupytext", reason="the test extra (pip install -e '.[test]') runs the lectures")


@lru_cache(maxsize=None)
def _cells(stem: str) -> tuple[tuple[str, str], ...]:
    """(cell type, source) of the lecture ``stem``, read from its .py."""
    return tuple((c.cell_type, c.source) for c in _jupytext().read(LECTURES / f"{stem}.py").cells)


def _level2_sections(stem: str) -> dict[str, str]:
    """Every ``## …`` heading of the lecture → the text (markdown and code) up to the next one."""
    sections: dict[str, str] = {}
    current = None
    for cell_type, source in _cells(stem):
        for line in source.splitlines():
            if cell_type == "markdown" and line.startswith("## "):
                current = line
                sections[current] = ""
            if current is not None:
                sections[current] += line + "\n"
    return sections


def _numbered_sections(stem: str) -> dict[int, str]:
    return {int(SECTION.match(h).group(1)): text for h, text in _level2_sections(stem).items() if SECTION.match(h)}


def _exercises(stem: str) -> list[int]:
    return [int(EXERCISE.match(h).group(1)) for h in _level2_sections(stem) if EXERCISE.match(h)]


def _render_module():
    spec = importlib.util.spec_from_file_location("lectures_render", LECTURES / "render.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _script_env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env.pop("LAGO_CVX_FIGURES", None)
    env["MPLBACKEND"] = "Agg"
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env.update(extra)
    return env


# ----------------------------------------------------------------------------- the notebooks
def test_there_are_lectures():
    assert SOURCES, f"no lectures found in {LECTURES}"


@pytest.mark.parametrize("src", SOURCES, ids=IDS)
def test_pair_in_sync(src):
    jupytext = _jupytext()
    ipynb = src.with_suffix(".ipynb")
    assert ipynb.exists(), f"{ipynb.name} missing: run `python lectures/render.py {src.name.split('_')[0]}`"
    a = [(c.cell_type, c.source.strip()) for c in jupytext.read(src).cells]
    b = [(c.cell_type, c.source.strip()) for c in jupytext.read(ipynb).cells]
    assert a == b, f"{src.name} and {ipynb.name} differ: run `jupytext --sync {src}` (or render it again)"


@pytest.mark.parametrize("src", SOURCES, ids=IDS)
def test_notebook_holds_rendered_outputs(src):
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(src.with_suffix(".ipynb"), as_version=4)
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    hint = f"run `python lectures/render.py {src.name.split('_')[0]}`"
    assert outputs, f"{src.name[:-3]}.ipynb holds no outputs: {hint}"
    assert any("image/png" in o.get("data", {}) for o in outputs), f"no figure stored: {hint}"
    errors = [o.get("ename", "") + ": " + o.get("evalue", "") for o in outputs if o.output_type == "error"]
    assert not errors, f"stored outputs hold errors {errors}: fix the lecture and {hint}"
    volatile = [c.get("id") for c in nb.cells if "execution" in c.get("metadata", {})]
    assert not volatile and "version" not in nb.metadata.get("language_info", {}), \
        f"volatile metadata (timestamps, versions) stored: {hint}"


@pytest.mark.parametrize("src", SOURCES, ids=IDS)
def test_lecture_executes(src, tmp_path):
    _jupytext()
    pytest.importorskip("nbclient")
    render = _render_module()
    start = time.perf_counter()
    nb = render.execute(src, figures=tmp_path)            # raises CellExecutionError on a failing cell
    seconds = time.perf_counter() - start
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"]
    assert not errors
    assert render.count_figures(nb) >= 1, "the lecture shows no figure"
    assert seconds < LECTURE_SECONDS_LIMIT, f"{src.stem} took {seconds:.0f} s (budget: 60 s)"


# ----------------------------------------------------------------------------- exercises
#: The metadata of a solution cell: collapsed in Jupyter (output shown), hidden behind a toggle in the site.
SOLUTION_TAGS = {"solution", "hide-cell"}
SOLUTION_JUPYTER = {"source_hidden": True, "outputs_hidden": False}
#: The site's toggle of a solution cell says what it hides (myst-nb's cell-level ``code_prompt_show``).
SOLUTION_PROMPT = "Solution and Discussion"


def _notebook_cells(stem: str):
    return _jupytext().read(LECTURES / f"{stem}.py").cells


@pytest.mark.parametrize("src", SOURCES, ids=IDS)
def test_exercises_are_numbered(src):
    numbers = _exercises(src.stem)
    assert 2 <= len(numbers) <= 3, f"{src.stem}: {len(numbers)} '## Exercise N — Title' headings (2 or 3 wanted)"
    assert numbers == list(range(1, len(numbers) + 1)), f"{src.stem}: exercises numbered {numbers}"


@pytest.mark.parametrize("src", SOURCES, ids=IDS)
def test_every_exercise_has_a_hint_a_checked_stub_and_a_hidden_solution(src):
    """Each exercise: its markdown gives a **Hint.**; the next cell is the stub (``# your solution here``, a ``def``
    whose body raises NotImplementedError, and a call of a ``check_…`` of ``lago_cvx.exercises`` on it); the cell
    after is the "Solution and Discussion", tagged ``solution`` and ``hide-cell``, collapsed in Jupyter, defining
    the same function and calling the same check with ``.require()``."""
    from lago_cvx import exercises

    cells = _notebook_cells(src.stem)
    starts = [i for i, c in enumerate(cells) if c.cell_type == "markdown" and EXERCISE.search(c.source.lstrip())]
    assert len(starts) == len(_exercises(src.stem)), f"{src.stem}: each '## Exercise N' heading starts its own markdown cell"
    for number, start in enumerate(starts, 1):
        where = f"{src.stem} exercise {number}"
        assert "**Hint.**" in cells[start].source, f"{where}: no '**Hint.**'"
        assert start + 2 < len(cells), f"{where}: no stub and solution cells after it"
        stub, solution = cells[start + 1], cells[start + 2]
        assert stub.cell_type == "code" and stub.source.startswith("# your solution here"), \
            f"{where}: the next cell is not a code cell starting '# your solution here'"
        calls = re.findall(r"^(check_\w+)\((\w+)\)$", stub.source, re.MULTILINE)
        assert len(calls) == 1 and hasattr(exercises, calls[0][0]), f"{where}: the stub calls no check of lago_cvx.exercises"
        check, name = calls[0]
        assert re.search(rf"^def {name}\(.*\n(\s+.*\n)*\s+raise NotImplementedError", stub.source, re.MULTILINE), \
            f"{where}: the stub does not define {name}(...) with a body to fill in"
        assert solution.cell_type == "code" and SOLUTION_TAGS <= set(solution.metadata.get("tags", [])), \
            f"{where}: the cell after the stub is not tagged {sorted(SOLUTION_TAGS)}"
        assert solution.metadata.get("jupyter") == SOLUTION_JUPYTER, f"{where}: the solution is not collapsed in Jupyter"
        assert solution.metadata.get("mystnb", {}).get("code_prompt_show") == SOLUTION_PROMPT, \
            f"{where}: the site's toggle does not say '{SOLUTION_PROMPT}'"
        assert solution.source.startswith("# Solution and Discussion."), f"{where}: the solution starts otherwise"
        assert re.search(rf"^def {name}\(", solution.source, re.MULTILINE) and f"{check}({name}).require()" in solution.source, \
            f"{where}: the solution does not define {name} and call {check}({name}).require()"


@pytest.mark.parametrize("src", SOURCES, ids=IDS)
def test_the_stored_solutions_pass_their_checks(src):
    """The rendered notebook proves its solutions: each solution cell's output ends with its check's ✓ line, and
    each stub's shows the check's ✗ line (the body is not written)."""
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(src.with_suffix(".ipynb"), as_version=4)
    solutions = [c for c in nb.cells if c.cell_type == "code" and "solution" in c.metadata.get("tags", [])]
    assert len(solutions) == len(_exercises(src.stem)), f"{src.stem}: re-render it (python lectures/render.py)"
    for cell in solutions:
        shown = [o.get("data", {}).get("text/plain", "") for o in cell.get("outputs", []) if o.output_type == "execute_result"]
        assert shown and shown[-1].startswith("✓ "), f"{src.stem}: a solution's check does not pass: {shown}"
    for cell in (c for c in nb.cells if c.cell_type == "code" and c.source.startswith("# your solution here")):
        shown = [o.get("data", {}).get("text/plain", "") for o in cell.get("outputs", []) if o.output_type == "execute_result"]
        assert shown and shown[-1].startswith("✗ ") and "not written yet" in shown[-1], \
            f"{src.stem}: a stub's check does not say that its body is missing: {shown}"


def test_some_exercises_are_set_mid_lecture():
    """At least three lectures set an exercise before their last numbered section ends."""
    mid = []
    for src in SOURCES:
        headings = [line for kind, text in _cells(src.stem) if kind == "markdown" for line in text.splitlines()
                    if line.startswith("## ")]
        sections = [k for k, h in enumerate(headings) if SECTION.match(h)]
        if any(EXERCISE.match(h) for h in headings[:sections[-1]] if sections):
            mid.append(src.stem)
    assert len(mid) >= 3, f"exercises mid-lecture only in {mid}"


@pytest.mark.parametrize("src", SOURCES, ids=IDS)
def test_notation_table_and_summary(src):
    """Every lecture has a notation table (a markdown table after '**Notation**') and a '**Summary.**'."""
    text = "\n".join(t for kind, t in _cells(src.stem) if kind == "markdown")
    assert "**Summary.**" in text, f"{src.stem}: no '**Summary.**'"
    notation = text.find("**Notation")
    assert notation >= 0, f"{src.stem}: no '**Notation**'"
    assert re.search(r"^\| symbol \| meaning \|", text[notation:notation + 3000], re.MULTILINE), \
        f"{src.stem}: the notation is not a table ('| symbol | meaning | … |')"


# ----------------------------------------------------------------------------- the course as a text
#: No lecture file is longer than this (a longer one is split, as lecture 4 is into 04a and 04b).
MAX_LECTURE_LINES = 650
CITE = re.compile(r"\{cite(?::\w+)?\}`[^`]+`")


@pytest.mark.parametrize("src", SOURCES, ids=IDS)
def test_lecture_length(src):
    lines = src.read_text(encoding="utf-8").count("\n")
    assert lines <= MAX_LECTURE_LINES, f"{src.name}: {lines} lines (at most {MAX_LECTURE_LINES}: split it)"


def test_lectures_cite_the_bibliography():
    citing = [src.name for src in SOURCES if CITE.search(src.read_text(encoding="utf-8"))]
    assert len(citing) >= 3, f"{{cite}} roles in {citing} only (at least 3 lectures should cite the reading list)"


def test_index_is_a_syllabus():
    index = (LECTURES / "index.md").read_text(encoding="utf-8")
    for heading in ("## Prerequisites", "## Syllabus", "## Reading list", "## Bibliography"):
        assert heading in index, f"index.md has no '{heading}'"
    assert "lago-cvx datasets fetch" in index and "</bibliography>" in index  # the site's bibliography page
    rows = {r[0]: r for r in _table_rows(index[index.index("## Syllabus"):index.index("## Reading list")])}
    for src in SOURCES:
        number = src.name.split("_")[0]
        assert number in rows, f"the syllabus has no row for lecture {number}"
        assert re.fullmatch(r"\d+(\.\d+)?", rows[number][-1]), f"lecture {number}: no hours in the syllabus"
    for key in ("carlone2011rss", "carlone2014ijrr", "rosen2019sesync", "carlone2015icra"):
        assert f"`{key}`" in index, f"the reading list does not cite {key}"


@pytest.mark.parametrize("src", SOURCES, ids=IDS)
def test_checks_are_hidden_in_the_site(src):
    """Every check sits in a cell tagged remove-input: the site shows its ✓ line, not its code, and the narrative
    cells read as a text (issue 32)."""
    nb = _jupytext().read(src)
    calls = hidden = 0
    for cell in nb.cells:
        if cell.cell_type == "code":
            n = sum(isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "check"
                    for node in ast.walk(ast.parse(cell.source)))
            calls += n
            hidden += n if "remove-input" in cell.metadata.get("tags", []) else 0
    assert hidden == calls, f"{src.stem}: only {hidden} of {calls} checks in remove-input cells"


#: The lectures that carry the course's running example (issue 32): the same small world, and INTEL for real data.
RUNNING_LECTURES = ("01", "02", "03", "04a", "04b", "05", "06")
#: A call that draws a world of its own.
OWN_WORLD = re.compile(r"\b(random_graph|manhattan_world|circle_world|section_v_world|grid_world|sphere_world)\(")
#: The comment that must stand on such a line, or on the line before it, saying why.
OWN_WORLD_REASON = re.compile(r"#\s*own world:\s*\S.{8,}")


@pytest.mark.parametrize("src", [s for s in SOURCES if s.name.split("_")[0] in RUNNING_LECTURES],
                         ids=lambda s: s.stem)
def test_running_example_carries_through(src):
    """Lectures 01–06 work on one running example (``course.running_example()``, beside the intuition figure
    that draws it) and on INTEL; a section that needs a world of its own says why in an ``# own world: …``
    comment on the line that draws it or the line before."""
    code = [source for cell_type, source in _cells(src.stem) if cell_type == "code"]
    uses = sum("running_example()" in cell for cell in code)
    assert uses >= 3, f"{src.stem}: the running example is used in {uses} code cells (at least 3)"
    assert any("INTEL_P_toro" in cell for cell in code), f"{src.stem}: INTEL (carlone/INTEL_P_toro.graph) is not used"
    unexplained = []
    for cell in code:
        lines = cell.splitlines()
        for k, line in enumerate(lines):
            if OWN_WORLD.search(line.split("#")[0]) and not (
                    OWN_WORLD_REASON.search(line) or (k > 0 and OWN_WORLD_REASON.search(lines[k - 1]))):
                unexplained.append(line.strip())
    assert not unexplained, f"{src.stem}: worlds of their own without '# own world: <why>': {unexplained}"


def _lecture_helpers():
    from lago_cvx import course

    return course


@pytest.mark.parametrize("noise", ["proportional", "isotropic"])
def test_section_v_world_states_the_papers_rule(noise):
    """Lecture 6's Table II world: information 1/σ² with σ = k·|measured component| + floor (the paper's
    first scenario), whichever noise the measurements carry; the measurement errors are as drawn."""
    helpers = _lecture_helpers()
    graph, truth = helpers.section_v_world(200, seed=3, noise=noise)
    rule = helpers.SECTION_V_RULE
    measured = np.column_stack([graph.delta_l, graph.delta])
    k = np.array([rule["k_t"], rule["k_t"], rule["k_theta"]])
    floor = np.array([rule["floor_t"], rule["floor_t"], rule["floor_theta"]])
    sigma = k * np.abs(measured) + floor
    diagonal = graph.information[:, [0, 1, 2], [0, 1, 2]]
    np.testing.assert_allclose(diagonal, 1.0 / sigma**2, rtol=1e-12)
    assert not np.any(graph.information - np.einsum("ka,ab->kab", diagonal, np.eye(3)))
    import lago_cvx as lc

    exact = lc.between(truth[graph.tails], truth[graph.heads])
    error = measured - exact
    error[:, 2] = (error[:, 2] + np.pi) % (2 * np.pi) - np.pi
    drawn = k * np.abs(exact) + floor if noise == "proportional" else np.array([0.02, 0.02, 0.01])
    z = error / drawn
    assert abs(z.std() - 1) < 0.1 and np.abs(z).max() < 6, f"standardized errors: std {z.std():.3f}, max {np.abs(z).max():.1f}"


# ----------------------------------------------------------------------------- wording
#: Words of the people who write the course, not of the course: in prose (markdown, comments, strings
#: with spaces), outside `code spans`.
INTERNAL = re.compile(r"\bseed\b|\bbrief\b|as formulated here|datasets README", re.IGNORECASE)
MPL_USE = re.compile(r"\b(matplotlib|mpl)\.use\s*\(")
CODE_SPAN = re.compile(r"`+[^`\n]*`+")
#: Replacement fields of f-strings ({seed}, {x:.2f}) are code, not prose.
FIELD = re.compile(r"\{[^{}\n]*\}")
#: Files in lectures/ that are not part of the course text (none at present).
NOT_COURSE: set[str] = set()


def _prose_of_code(text: str) -> list[str]:
    """Comments, and string literals that read like prose (contain a space), of Python source."""
    prose = []
    kinds = {tokenize.COMMENT, tokenize.STRING} | {getattr(tokenize, "FSTRING_MIDDLE", tokenize.STRING)}
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT or (tok.type in kinds and " " in tok.string):
            prose.append(FIELD.sub("", tok.string) if tok.type != tokenize.COMMENT else tok.string)
    return prose


def _course_texts() -> list[tuple[str, str, str]]:
    """(file, kind, text) for every piece of the course: lectures, helpers, exercises' checks, site pages."""
    texts = []
    helpers = [ROOT / "lago_cvx" / "course.py", ROOT / "lago_cvx" / "course_figures.py"]
    for path in sorted(LECTURES.glob("*.py")) + helpers + sorted((ROOT / "lago_cvx" / "exercises").glob("*.py")):
        name = str(path.relative_to(ROOT))
        if path in SOURCES:
            for cell_type, source in _cells(path.stem):
                if cell_type == "markdown":
                    texts.append((name, "prose", source))
                else:
                    texts.append((name, "code", source))
                    texts += [(name, "prose", p) for p in _prose_of_code(source)]
        else:
            source = path.read_text(encoding="utf-8")
            texts.append((name, "code", source))
            texts += [(name, "prose", p) for p in _prose_of_code(source)]
    for path in sorted(LECTURES.glob("*.md")):
        if path.name not in NOT_COURSE:
            texts.append((str(path.relative_to(ROOT)), "prose", path.read_text(encoding="utf-8")))
    return texts


def test_no_matplotlib_use_and_no_internal_wording():
    _jupytext()
    problems = []
    for name, kind, text in _course_texts():
        if MPL_USE.search(text):
            problems.append(f"{name}: matplotlib.use (figures show inline; course.show writes files)")
        if kind == "prose":
            for match in INTERNAL.finditer(CODE_SPAN.sub("", text)):
                problems.append(f"{name}: internal wording {match.group(0)!r}")
    assert not problems, "\n".join(sorted(set(problems)))


# ----------------------------------------------------------------------------- concordance
#: The items the paper states without a number (SEED.md, "Also stated in the text"), as labelled here.
UNNUMBERED = ["cycle / circuit", "regularization steps (Section V)", "abstract: refinement often unnecessary"]
ROW_LECTURE = re.compile(r"^(\d\d[a-z]?_\w+) §(\d+)$")
DOTTED = re.compile(r"^[A-Za-z_][\w.]*$")


def _table_rows(text: str) -> list[list[str]]:
    rows = []
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("|") and line.endswith("|") and not re.fullmatch(r"[\s|:-]+", line):
            rows.append([c.strip() for c in line[1:-1].split(" | ")])
    return rows


def seed_labels() -> list[str]:
    """Every item of the paper, as SEED.md labels it, in its order."""
    if not SEED_MD.is_file():
        pytest.skip(f"the paper's item list is not at {SEED_MD}")
    text = SEED_MD.read_text(encoding="utf-8")
    labels = []
    experiment = text.index("## Experiment")
    also = re.search(r"^Also stated in the text.*?(?=\n\n)", text, re.MULTILINE | re.DOTALL)
    assert also, "SEED.md has no 'Also stated in the text' paragraph"
    for word in ("cycle", "circuit", "regularization steps of Section V", "abstract", "refinement"):
        assert word in also.group(0), f"SEED.md's 'Also stated' paragraph no longer mentions {word!r}"
    for index, part in enumerate((text[:experiment], text[experiment:])):
        for cells in _table_rows(part):
            first = cells[0]
            if first in ("eq.", "label", "item"):
                continue
            number = re.fullmatch(r"\((\d+)\)", first)
            labels.append(f"eq. ({number.group(1)})" if number else re.sub(r"\s*\(.*\)$", "", first))
        if index == 0:                      # the unnumbered items come after the numbered results
            labels += UNNUMBERED
    return labels


def concordance_rows() -> list[list[str]]:
    assert CONCORDANCE.is_file(), f"{CONCORDANCE} missing"
    rows = [r for r in _table_rows(CONCORDANCE.read_text(encoding="utf-8")) if r[0] != "label"]
    bad = [r for r in rows if len(r) != 4]
    assert not bad, f"rows without exactly 4 cells (label | lecture | package | tests): {bad}"
    return rows


def _backticked(cell: str) -> list[str]:
    return re.findall(r"`([^`]+)`", cell)


def _resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        try:
            for attr in parts[cut:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return False
        return True
    return False


def test_seed_labels_are_read():
    labels = seed_labels()
    assert [f"eq. ({i})" for i in range(1, 24)] == [lb for lb in labels if lb.startswith("eq. (")]
    for label in ("Lemma 1", "Proposition 1", "Theorem 3", "Remark 2", "Table I", "Table II", "Fig. 3"):
        assert label in labels


def test_concordance_covers_the_paper():
    labels = seed_labels()
    rows = {r[0] for r in concordance_rows()}
    missing = [lb for lb in labels if lb not in rows]
    assert not missing, f"items of the paper without a row in {CONCORDANCE.name}: {missing}"


def _cell_names(label: str, column: str, cell: str, example: str, problems: list) -> list:
    """The backticked names of a concordance cell; a problem is noted when it names nothing."""
    names = _backticked(cell)
    if not names:
        problems.append(f"{label}: {column} cell {cell!r} names nothing (use {example} or '— reason')")
    return names


def test_concordance_rows_hold():
    _jupytext()
    labels = seed_labels()
    rows = concordance_rows()
    problems = []
    seen = [r[0] for r in rows]
    problems += [f"unknown label {lb!r} (not an item of SEED.md)" for lb in seen if lb not in labels]
    problems += [f"label {lb!r} has {seen.count(lb)} rows" for lb in sorted(set(seen)) if seen.count(lb) > 1]
    known = [lb for lb in seen if lb in labels]
    if known != sorted(known, key=labels.index):
        problems.append("rows are not in the paper's order (SEED.md)")
    for label, lecture, package, tests in rows:
        if not lecture.startswith("—"):
            for ref in lecture.split("; "):
                m = ROW_LECTURE.match(ref.strip())
                if not m:
                    problems.append(f"{label}: lecture {ref!r} is not 'NN_name §K'")
                    continue
                stem, k = m.group(1), int(m.group(2))
                if not (LECTURES / f"{stem}.py").is_file():
                    problems.append(f"{label}: no lecture {stem}")
                    continue
                section = _numbered_sections(stem).get(k)
                if section is None:
                    problems.append(f"{label}: {stem} has no section '## {k}.'")
                elif label not in section:
                    problems.append(f"{label}: {stem} §{k} does not contain {label!r}")
        if not package.startswith("—"):
            for name in _cell_names(label, "package", package, "`a.b.c`", problems):
                if not DOTTED.match(name) or not _resolves(name):
                    problems.append(f"{label}: package name {name!r} does not import")
        if not tests.startswith("—"):
            for test_id in _cell_names(label, "tests", tests, "`tests/f.py::test_x`", problems):
                path, _, name = test_id.partition("::")
                name = name.split("::")[-1].split("[")[0]
                file = ROOT / path
                if not path.startswith("tests/") or not file.is_file():
                    problems.append(f"{label}: test file {path!r} does not exist")
                elif not name or not re.search(rf"^\s*(async\s+)?def {re.escape(name)}\(", file.read_text(encoding="utf-8"),
                                               re.MULTILINE):
                    problems.append(f"{label}: no 'def {name}' in {path}")
    assert not problems, "\n".join(problems)


# ----------------------------------------------------------------------------- the site and a clean run
def test_course_site_builds(tmp_path):
    pytest.importorskip("sphinx", reason="the course site needs the course extra (sphinx, myst-nb)")
    for module in ("myst_nb", "sphinx_design", "sphinxcontrib.bibtex"):
        pytest.importorskip(module, reason="the site needs the course extra (sphinx, myst-nb, sphinx-design, "
                                           "sphinxcontrib-bibtex)")
    run = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q",
                          "-d", str(tmp_path / "doctrees"), str(ROOT / "docs"), str(tmp_path / "html")],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, f"the site does not build cleanly:\n{run.stdout[-3000:]}\n{run.stderr[-6000:]}"
    for src in SOURCES:
        assert (tmp_path / "html" / "course" / f"{src.stem}.html").is_file()


def test_running_a_lecture_as_a_script_leaves_the_checkout_clean(tmp_path):
    """A copy of the checkout (tracked and untracked files, as git lists them) becomes a repository;
    the quickest lecture runs there as a plain script; git then sees no change and no new file."""
    git = shutil.which("git")
    if git is None or subprocess.run([git, "rev-parse"], cwd=ROOT, capture_output=True).returncode != 0:
        pytest.skip("not a git checkout")
    src = next((s for s in SOURCES if s.name.startswith(SCRIPT_LECTURE)), None)
    if src is None:
        pytest.skip(f"no lecture {SCRIPT_LECTURE}")
    listed = subprocess.run([git, "ls-files", "-z", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True,
                            check=True).stdout.decode().split("\0")
    copy = tmp_path / "checkout"
    for rel in filter(None, listed):
        if (ROOT / rel).is_file():
            (copy / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, copy / rel)

    def git_in_copy(*args):
        return subprocess.run([git, "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=copy,
                              capture_output=True, text=True, check=True).stdout

    git_in_copy("init", "-q")
    git_in_copy("add", "-A")
    git_in_copy("commit", "-q", "-m", "copy")
    assert git_in_copy("status", "--porcelain", "--untracked-files=all") == ""
    from conftest import DATASETS

    extra = {"LAGO_CVX_DATASETS": str(DATASETS)} if DATASETS.is_dir() else {}
    env = _script_env(**extra)
    env["PYTHONPATH"] = os.pathsep.join([str(copy)] + env["PYTHONPATH"].split(os.pathsep)[1:])
    run = subprocess.run([sys.executable, src.name], cwd=copy / "lectures", env=env, capture_output=True,
                         text=True, encoding="utf-8", timeout=600)
    assert run.returncode == 0, f"{src.name} as a script failed:\n{run.stdout[-2000:]}\n{run.stderr[-4000:]}"
    left = git_in_copy("status", "--porcelain", "--untracked-files=all")
    assert left == "", f"running {src.name} changed or left files:\n{left}"


def test_a_notebook_runs_alone_in_an_empty_folder(tmp_path):
    """The quickest lecture's notebook, copied alone into an empty folder, executes there with the installed
    package (``PYTHONPATH`` naming the project root, as an installed ``lago_cvx`` would be found): the course's
    helpers live in ``lago_cvx.course`` and no lecture reads a file of the checkout. Its install cell does not
    run (``lago_cvx`` imports), and the folder holds nothing but the notebook afterwards."""
    _jupytext()
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    src = next((s for s in SOURCES if s.name.startswith(SCRIPT_LECTURE)), None)
    if src is None:
        pytest.skip(f"no lecture {SCRIPT_LECTURE}")
    alone = tmp_path / "alone"
    alone.mkdir()
    notebook = alone / src.with_suffix(".ipynb").name
    shutil.copy2(src.with_suffix(".ipynb"), notebook)
    nb = nbformat.read(notebook, as_version=4)
    from conftest import DATASETS

    env = _script_env(**({"LAGO_CVX_DATASETS": str(DATASETS)} if DATASETS.is_dir() else {}))
    env.pop("MPLBACKEND", None)
    nbclient.NotebookClient(nb, timeout=LECTURE_SECONDS_LIMIT, kernel_name="python3",
                            resources={"metadata": {"path": str(alone)}}).execute(env=env)
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"]
    assert not errors, errors
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "pip install" not in text and "Successfully installed" not in text, "the install cell ran"
    assert sorted(p.name for p in alone.iterdir()) == [notebook.name], "the notebook left files in its folder"
