"""Render the course: execute the lectures and store their outputs in the notebooks.

    python lectures/render.py              # every lecture
    python lectures/render.py 02 04a       # the lectures whose number is given (04: both parts of 4)
    python lectures/render.py --site       # build the course site from the stored outputs (no execution)

Each lecture ``NN_name.py`` (py:percent, the reviewed source) is executed top to bottom with nbclient
(kernel ``python3``, working directory ``lectures/``) and written to ``NN_name.ipynb`` *with* its
outputs; the jupytext pairing (``jupytext.toml``) is kept, so ``jupytext --sync`` keeps the outputs too.
The kernel runs with

* ``LAGO_CVX_FIGURES=<project>/figures``: every ``lago_cvx.course.show`` also writes ``NN_*.png`` and ``.svg``
  there (the lecture's old ``NN_*`` figure files are removed first, so none goes stale);
* ``LAGO_CVX_STATIC=1``: a ``lago_cvx.course.interactive`` figure is drawn once at its sliders' defaults, so the
  notebook and the site store a plain figure (a reader's live kernel shows the sliders);
* ``SOURCE_DATE_EPOCH=0`` and ``PYTHONHASHSEED=0``: no dates in the figure files, a fixed set order;
* ``PYTHONPATH`` starting with the project root: this checkout's ``lago_cvx`` is the one executed;
* ``MPLBACKEND`` unset: the kernel's inline backend shows the figures.

Volatile metadata is stripped so that re-rendering an unchanged lecture changes no byte: no execution
timestamps, no kernel or language versions, cell ids derived from the cell's content, consecutive stream
outputs merged. A lecture that raises is reported and its notebook is left as it was; the command then
exits with status 1. One line per lecture tells its run time and the number of figures it shows.

The course is part of the project's site (Sphinx + myst-nb; ``docs/conf.py``, the course linked in as
``docs/course``), which renders the stored outputs only: ``--site`` runs
``python -m sphinx -b html -W --keep-going docs docs/_build/html``.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
import time
from pathlib import Path

LECTURES = Path(__file__).resolve().parent
ROOT = LECTURES.parent
FIGURES = ROOT / "figures"
DOCS = ROOT / "docs"
SITE = DOCS / "_build" / "html"

#: ``language_info`` fields kept in the notebook (the kernel's ``version`` is dropped).
_LANGUAGE_INFO_KEPT = ("name", "codemirror_mode", "file_extension", "mimetype", "nbconvert_exporter",
                       "pygments_lexer")
KERNELSPEC = {"display_name": "Python 3", "language": "python", "name": "python3"}


def lecture_number(source: Path) -> str:
    """The number of the lecture ``NN_name.py`` or ``NNx_name.py`` (a lecture split in parts): ``NN`` or ``NNx``."""
    return source.name.split("_", 1)[0]


def lecture_sources(numbers=()) -> list[Path]:
    """The lectures ``NN_name.py`` / ``NNx_name.py`` in order; only those whose number is in ``numbers`` if given
    (``04`` names every part of lecture 4, ``04a`` one part)."""
    sources = sorted(LECTURES.glob("[0-9][0-9]*_*.py"))
    if numbers:
        wanted = {n.zfill(2) for n in numbers}
        chosen = [s for s in sources if lecture_number(s) in wanted or lecture_number(s)[:2] in wanted]
        unknown = {w for w in wanted if not any(lecture_number(s) == w or lecture_number(s)[:2] == w for s in sources)}
        if unknown:
            raise SystemExit(f"render.py: no lecture numbered {', '.join(sorted(unknown))} in {LECTURES}")
        sources = chosen
    return sources


def kernel_environment(figures: Path | None = FIGURES) -> dict[str, str]:
    """The environment the kernel inherits (see the module docstring)."""
    env = dict(os.environ)
    env.pop("MPLBACKEND", None)
    env["LAGO_CVX_STATIC"] = "1"
    env["SOURCE_DATE_EPOCH"] = "0"
    env["PYTHONHASHSEED"] = "0"
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    if figures is None:
        env.pop("LAGO_CVX_FIGURES", None)
    else:
        env["LAGO_CVX_FIGURES"] = str(figures)
    return env


def execute(source: Path, figures: Path | None = FIGURES, timeout: int = 600):
    """Execute the lecture ``source`` (a ``.py``) and return the notebook with its outputs.

    Raises ``nbclient.exceptions.CellExecutionError`` when a cell raises."""
    import jupytext
    from nbclient import NotebookClient

    nb = jupytext.read(source)
    nb.metadata["kernelspec"] = dict(KERNELSPEC)
    NotebookClient(nb, timeout=timeout, kernel_name="python3", record_timing=False,
                   resources={"metadata": {"path": str(LECTURES)}}).execute(env=kernel_environment(figures))
    return normalize(nb)


def _merge_streams(outputs: list) -> list:
    merged: list = []
    for out in outputs:
        if (out.get("output_type") == "stream" and merged and merged[-1].get("output_type") == "stream"
                and merged[-1].get("name") == out.get("name")):
            merged[-1]["text"] += out["text"]
        else:
            merged.append(out)
    return merged


def normalize(nb):
    """Strip what changes from run to run without the lecture changing (in place; returns ``nb``)."""
    nb.metadata = {key: value for key, value in nb.metadata.items() if key in ("kernelspec", "language_info")}
    nb.metadata["kernelspec"] = dict(KERNELSPEC)
    info = nb.metadata.get("language_info", {})
    nb.metadata["language_info"] = {k: info[k] for k in _LANGUAGE_INFO_KEPT if k in info} or {"name": "python"}
    nb.nbformat, nb.nbformat_minor = 4, 5
    seen: dict[str, int] = {}
    for cell in nb.cells:
        cell.metadata = {k: v for k, v in cell.metadata.items() if k not in ("execution", "collapsed", "scrolled")}
        digest = hashlib.sha1(f"{cell.cell_type}\0{cell.source}".encode()).hexdigest()[:8]
        seen[digest] = seen.get(digest, 0) + 1
        cell["id"] = digest if seen[digest] == 1 else f"{digest}-{seen[digest]}"
        if cell.cell_type == "code":
            cell.outputs = _merge_streams(cell.get("outputs", []))
            for out in cell.outputs:
                out.get("metadata", {}).pop("execution", None)
    return nb


def count_figures(nb) -> int:
    return sum("image/png" in out.get("data", {}) for cell in nb.cells if cell.cell_type == "code"
               for out in cell.get("outputs", []))


def write(nb, target: Path) -> None:
    """Write ``nb`` as ``target`` (an ``.ipynb``), then touch the paired ``.py`` so that Jupyter, which
    refuses a paired notebook newer than its text file, opens the pair as it is."""
    import nbformat

    text = nbformat.writes(nb, version=4)
    if not text.endswith("\n"):
        text += "\n"
    if not target.exists() or target.read_text(encoding="utf-8") != text:
        target.write_text(text, encoding="utf-8")
    paired = target.with_suffix(".py")
    if paired.exists():
        os.utime(paired)


def render(source: Path) -> bool:
    """Execute one lecture and store its outputs; print its summary line; True on success."""
    from nbclient.exceptions import CellExecutionError

    prefix = lecture_number(source)
    for old in sorted(FIGURES.glob(f"{prefix}_*")):
        if old.suffix in (".png", ".svg"):
            old.unlink()
    start = time.perf_counter()
    try:
        nb = execute(source)
    except CellExecutionError as exc:
        print(f"{source.stem:20s} FAILED after {time.perf_counter() - start:5.1f} s "
              f"(notebook left as it was):\n{exc}", flush=True)
        return False
    seconds = time.perf_counter() - start
    write(nb, source.with_suffix(".ipynb"))
    files = sum(1 for f in FIGURES.glob(f"{prefix}_*") if f.suffix in (".png", ".svg"))
    print(f"{source.stem:20s} {seconds:5.1f} s  {count_figures(nb):2d} figures shown  "
          f"{files:2d} files in figures/", flush=True)
    return True


def build_site(outdir: Path = SITE, *extra: str) -> int:
    """``python -m sphinx -b html -W --keep-going docs <outdir>``: the site, with the course from the stored
    outputs."""
    command = [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", *extra, str(DOCS), str(outdir)]
    print(" ".join(command[1:]), flush=True)
    return subprocess.call(command, cwd=ROOT)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("numbers", nargs="*", metavar="NN", help="lecture numbers (default: all)")
    parser.add_argument("--site", action="store_true",
                        help=f"build the site (the course included) into {SITE.relative_to(ROOT)} from the stored "
                             "outputs instead of executing lectures")
    args = parser.parse_args(argv)
    if args.site:
        if args.numbers:
            parser.error("--site renders the stored outputs of every lecture: give no lecture numbers")
        return build_site()
    FIGURES.mkdir(exist_ok=True)
    results = [render(source) for source in lecture_sources(args.numbers)]
    return 0 if all(results) else 1


if __name__ == "__main__":
    sys.exit(main())
