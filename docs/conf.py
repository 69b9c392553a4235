"""Sphinx configuration of the lago_cvx site: the user guide, the API reference, the design notes, the
benchmark tables and the course (``course`` is a link to ``../lectures``; its notebooks are shown with the
outputs ``lectures/render.py`` stored, nothing is executed).

One command builds it (``python lectures/render.py --site`` runs the same)::

    python -m sphinx -b html -W --keep-going docs docs/_build/html
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # autodoc documents this checkout's package
sys.path.insert(0, str(Path(__file__).resolve().parent))  # _docstrings

project = "lago_cvx"
author = "the lago_cvx authors"
copyright = "the lago_cvx authors, BSD-3-Clause"

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx_design",
    "sphinxcontrib.bibtex",
]

# --- pages: MyST markdown and the stored notebooks
nb_execution_mode = "off"            # the outputs stored by lectures/render.py are shown as they are
nb_merge_streams = True
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
myst_heading_anchors = 3

root_doc = "index"
# The course's notebooks are its pages; their paired .py files, the benchmark scripts and everything Jupyter
# or a build leaves behind are not. An exercise's "Solution and Discussion" cell is tagged ``hide-cell``: myst-nb
# shows it folded behind a toggle, as Jupyter shows it collapsed.
exclude_patterns = [
    "_build", "course/_build", "**/.ipynb_checkpoints", "**/*.nbconvert.ipynb",
    "**/.jupyter_cache", "**/jupyter_execute", "**/.virtual_documents",
]
suppress_warnings = ["myst.header"]   # lectures may jump from the title (#) to a sub-section (###)

# --- the API reference
autodoc_member_order = "bysource"
autodoc_typehints = "none"          # the docstrings state every argument's shape and meaning
autodoc_default_options = {"members": True, "show-inheritance": False}
autosummary_generate = False

# --- the bibliography (one {bibliography} directive: bibliography.md; the lectures {cite} into it)
bibtex_bibfiles = ["course/references.bib"]
bibtex_default_style = "plain"
bibtex_reference_style = "author_year"

html_theme = "alabaster"
html_title = "lago_cvx"
html_theme_options = {"page_width": "1150px", "sidebar_width": "260px"}
html_show_sourcelink = False
html_last_updated_fmt = None         # no build date: the site is reproducible


def _map_linked_sources(app, env, docnames):
    """Let a markdown link inside ``course/`` find its page. Sphinx resolves a link's path through the
    ``course -> ../lectures`` link (``lectures/X.md``) and then finds no page there; this maps every
    page's resolved path to its page name as well."""
    project = env.project
    table = getattr(project, "_path_to_docname", None)
    if table is None:  # another Sphinx: such links then warn, and the build says so
        return
    for docname in project.docnames:
        path = Path(project.doc2path(docname, absolute=True))
        resolved = path.resolve()
        if resolved != path:
            table.setdefault(resolved, docname)


#: the API page's generated parts (``docs/api.md`` holds the markers)
CURATED_MARK = "<!-- curated API -->"
ENGINE_MARK = "<!-- engine -->"


def _curated_api() -> str:
    """The names ``lago_cvx`` exports, each linked to its documentation under its defining module."""
    import lago_cvx

    lines = ["```{eval-rst}", ".. autosummary::", "   :nosignatures:", ""]
    lines += [f"   ~lago_cvx.{module}.{name}" for module, names in lago_cvx._EXPORTS.items() for name in names]
    return "\n".join(lines + ["```", ""])


def _engine_api() -> str:
    """``lago_cvx.sparse``, the engine's one door, when this checkout has it."""
    import importlib.util

    if importlib.util.find_spec("lago_cvx.sparse") is None:
        return "The sparse engine's interface (`lago_cvx.sparse`) is not part of this checkout.\n"
    return "```{eval-rst}\n.. automodule:: lago_cvx.sparse\n```\n"


def _fill_api_page(app, docname, source):
    if docname == "api":
        source[0] = source[0].replace(CURATED_MARK, _curated_api()).replace(ENGINE_MARK, _engine_api())


def setup(app):
    app.connect("env-before-read-docs", _map_linked_sources)
    app.connect("source-read", _fill_api_page)
    app.connect("autodoc-process-docstring", _docstring_as_rst)
    return {"parallel_read_safe": True}


def _docstring_as_rst(app, what, name, obj, options, lines):
    from _docstrings import to_rst

    lines[:] = to_rst(lines)
