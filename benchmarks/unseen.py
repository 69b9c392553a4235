"""Section ``unseen`` of ``python benchmarks/run.py``: the default route on real pose graphs the package
was never tuned on.

Sources: the planar pose graphs that ship with GTSAM's Python wheel (``gtsam/Data``: ``pose2example.txt``,
``w100.graph`` (TORO, with EQUIV records), ``w20000.txt`` (edges only; its EDGE2 information is stored in
the g2o order, read with ``edge2_order="g2o"``)), found when the ``gtsam`` extra is installed, and every
``.g2o``/``.graph``/``.txt`` file of ``--unseen DIR`` (or ``$LAGO_CVX_UNSEEN``), e.g. Freiburg's FRH,
ais2klinik or M3500b fetched by the user. Nothing is copied into the project.

For each file: χ² of LAGO (default route; the paper's route, ``route="seed"``, when the odometric chain
is complete), and the lowest χ² that Gauss–Newton reaches from LAGO and from the file's own guess (or
dead reckoning) — a local minimum, the best known, not a certified one; the ratio LAGO / best.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import _bench
from lago_cvx import lago, odometry_guess, read_graph, refine
from lago_cvx.errors import LagoError

HEAD = ["file", "poses", "edges", "χ² LAGO default", "χ² LAGO seed route", "χ² best (GN)", "from",
        "default / best", "seed / best", "GN from default / best (iterations)", "LAGO [ms]"]

#: Where the files of the committed table's ``--unseen`` folder come from, by the start of their SHA-256
#: (public repositories at the commits named; nothing is copied into the project).
KNOWN_SOURCES = {
    "56868ab910e876e3": "gisbi-kim/nano-pgo@b85562f data/FRH_P_toro.graph (Freiburg, C. Stachniss)",
    "e388ebd8523987c1": "david-m-rosen/SE-Sync@9b631b6 data/ais2klinik.g2o",
    "55342238a0d45d72": "gisbi-kim/nano-pgo@b85562f data/input_M3500b_g2o.g2o (M3500 with extra rotation noise)",
    "4d87aaf96e1e04e4": "memorydump85/pyslam@cd6b3ba datasets/intel.g2o",
}

GTSAM_FILES = {"pose2example.txt": {}, "w100.graph": {}, "w20000.txt": {"edge2_order": "g2o"}}


def add_arguments(group) -> None:
    group.add_argument("--unseen", type=Path, default=os.environ.get("LAGO_CVX_UNSEEN"), metavar="DIR",
                       help="a folder of further pose graphs for the unseen section ($LAGO_CVX_UNSEEN)")


def _files(folder: Path | None) -> list[tuple[str, Path, dict]]:
    out = []
    try:
        import gtsam

        data = Path(gtsam.__file__).parent / "Data"
        out += [(f"gtsam/Data/{name}", data / name, kw) for name, kw in GTSAM_FILES.items() if (data / name).is_file()]
    except ImportError:
        pass
    if folder is not None and Path(folder).is_dir():
        for p in sorted(Path(folder).iterdir()):
            if p.suffix in (".g2o", ".graph", ".txt") and p.is_file():
                out.append((p.name, p, {}))
    return out


def run(args) -> str:
    import time

    files = _files(getattr(args, "unseen", None))
    if not files:
        return "# LAGO on unseen graphs\n\nskipped: no gtsam Data folder and no --unseen DIR."
    rows, sources = [], []
    for name, path, kw in files:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        where_from = KNOWN_SOURCES.get(digest[:16], "GTSAM's wheel" if name.startswith("gtsam/") else "the user's folder")
        sources.append(f"* `{name}`: {where_from}; SHA-256 {digest[:16]}…")
        try:
            g = read_graph(path, **kw)
        except LagoError as exc:
            rows.append([name, "–", "–", f"not read: {exc}", "", "", "", "", "", ""])
            continue
        t = time.perf_counter()
        res = lago(g)
        ms = 1000 * (time.perf_counter() - t)
        try:
            seed = lago(g, route="seed").chi2
        except LagoError:
            seed = None
        starts = {"LAGO": res.poses}
        starts["file guess" if g.initial is not None else "dead reckoning"] = (
            g.initial if g.initial is not None else odometry_guess(g, spanning_tree="bfs"))
        refined = {k: refine(g, x0, max_iterations=100) for k, x0 in starts.items()}
        best, where = min((r.chi2, k) for k, r in refined.items())
        best = min(best, res.chi2)
        from_lago = refined["LAGO"]
        rows.append([name, g.n_poses, g.n_edges, _bench.fmt(res.chi2), _bench.fmt(seed) if seed is not None else "–",
                     _bench.fmt(best), where, f"{res.chi2 / best:.4f}" if best > 0 else "–",
                     f"{seed / best:.3f}" if seed is not None and best > 0 else "–",
                     f"{from_lago.chi2 / best:.4f} ({from_lago.iterations})" if best > 0 else "–", f"{ms:.0f}"])
        print(" | ".join(map(str, rows[-1])), flush=True)
    return ("# LAGO on real graphs it was never tuned on\n\n"
            "χ² = Σ eᵀΩe in each file's own cost (`lago_cvx.conventions`). best = the lowest χ² Gauss–Newton reaches from LAGO or from the "
            "file's guess (dead reckoning along a BFS tree when the file has none): the best known local minimum, "
            "not a certified one. GN from default = Gauss–Newton (at most 100 iterations) started at the default "
            "route's estimate: what `lago-cvx solve --refine --max-iterations 100` ends at. seed = the paper's "
            "procedure (`route=\"seed\"`), – where the odometric chain is "
            "broken.\n\n" + _bench.table(HEAD, rows) + "\n\nFiles:\n\n" + "\n".join(sources))
