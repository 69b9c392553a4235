"""Section ``share`` of ``python benchmarks/run.py``: what a fraction of false edges means on each file — the
share of the loop closures that are false — and how much the trusted odometry can tell false loop closures
from true ones before any solver runs.

The protocol of ``robust`` (``lago_cvx.synthetic.add_false_loop_closures``) appends ⌊fraction · m⌋ false loop
closures to a file's m edges. Its fraction counts edges, odometry included; GNC and every consistency test see
the loop closures only. A file with few loop closures (MIT: 807 odometric edges, 20 loop closures) reaches the
same fraction with a far larger share of false loop closures than one with many (M3500: 1 954 of 5 453).

For intel, M3500, CSAIL and MIT at 10 % and 30 %, seeds 0 to ``--share-seeds`` − 1 (default 3), with c̄² = χ²₃(0.99)
= 11.34 (``lago_cvx.variants.consistency``, the odometric chain complete in every file):

* **single test**: the loop closures whose error at dead reckoning passes d²_k ≤ c̄² against the covariance of
  the odometry between their ends plus their own — true ones (the same on every seed) and false ones;
* **pairs** (where there are at most ``PCM_MAX_EDGES`` = 1000 loop closures, PCM's own limit): the pairs of loop
  closures whose cycle through the odometry passes d²_kl ≤ c̄² (Mangelson et al.'s pairwise consistency), among
  true–true, true–false and false–false pairs; and the maximum clique of consistent pairs that
  ``RobustSettings(start="pcm")`` starts GNC from: its size and how many false loop closures it holds;
* **robust LAGO** (``lago(graph, robust=True)``): false loop closures kept, true edges rejected, and the truncated
  cost Σ_k min(r_k², c̄²) over every edge at LAGO's estimate of the edges it accepts, minus the same at LAGO's
  estimate of the file's own (clean) edges: above 0, the clean classification is the lower, and the search
  missed it; below 0, the objective prefers a classification that keeps a false edge or drops a true one;
* pass as in ``robust``: every false edge rejected, at most 1 % of the true edges, and χ² of the clean edges after
  ``refine`` on the accepted edges within 0.1 % of the clean refined χ².

``--share-variants`` adds, on MIT at 30 % (seeds 0 to ``--share-seeds`` − 1), the other searches the package
offers — GNC from a PCM clique (``start="pcm"``), from both starts with the lower cost kept (``"best"``), μ × 1.2
per iteration, Geman–McClure, and the calibrated threshold of ``separable`` — scored the same way.
"""

from __future__ import annotations

import time

import numpy as np

import _bench
import separable
from lago_cvx import lago, refine
from lago_cvx.synthetic import add_false_loop_closures
from lago_cvx.variants import RobustSettings
from lago_cvx.variants.consistency import chain_consistency, maximum_clique, odometry_chain, pairwise_matrix
from lago_cvx.variants.gnc import PCM_MAX_EDGES, truncated_cost

FILES = ("se-sync/intel.g2o", "carlone/input_M3500_g2o.g2o", "se-sync/CSAIL.g2o", "se-sync/MIT.g2o")
QUICK_FILES = ("se-sync/MIT.g2o",)
FRACTIONS = (0.1, 0.3)
VARIANT_FILE, VARIANT_FRACTION = "se-sync/MIT.g2o", 0.3
VARIANTS = (("default", RobustSettings()), ('start="pcm"', RobustSettings(start="pcm")),
            ('start="best"', RobustSettings(start="best")), ("mu_factor=1.2", RobustSettings(mu_factor=1.2)),
            ('loss="gm"', RobustSettings(loss="gm")), ("calibrate=4.7", RobustSettings(calibrate=4.7)))
C2 = RobustSettings().c2


def add_arguments(group) -> None:
    group.add_argument("--share-seeds", type=int, default=3, metavar="N",
                       help="share section: seeds 0..N-1 per file and fraction (default 3)")
    group.add_argument("--share-variants", action="store_true",
                       help="share section: also the other robust settings on MIT + 30 %%")


def pair_rates(d2: np.ndarray, false: np.ndarray, c2: float) -> tuple[float, float, float]:
    """The shares of consistent pairs (d²_kl ≤ c2) among true–true, true–false and false–false pairs of loop
    closures, from their symmetric d² matrix (q, q) and which of them are false (q,) bool (NaN: no such pair)."""
    ok = d2 <= c2
    iu = np.triu_indices(false.size, 1)
    a, b, good = false[iu[0]], false[iu[1]], ok[iu]

    def share(mask):
        return float(good[mask].mean()) if mask.any() else float("nan")

    return share(~a & ~b), share(a != b), share(a & b)


def score(graph, go, idx, res, clean_chi2, clean_lago_cost) -> dict:
    """False kept, true rejected, truncated cost ours − the clean classification's (each at LAGO's estimate of its
    accepted edges) and pass, of a robust run ``res`` on the corrupted graph ``go``."""
    kept, wrong, ratio, ok = separable.score(graph, idx, res, clean_chi2)
    return dict(kept=kept, wrong=wrong, ratio=ratio, gap=truncated_cost(go, res.poses, C2) - clean_lago_cost, ok=ok)


def corrupted(graph, fraction, seed):
    """(corrupted graph, false edge indices, truncated cost of the clean classification at LAGO's estimate of the
    clean edges)."""
    go, idx = add_false_loop_closures(graph, fraction, seed=seed)
    keep = np.ones(go.n_edges, bool)
    keep[idx] = False
    return go, idx, truncated_cost(go, lago(go.subgraph_edges(keep)).poses, C2)


def run(args) -> str:
    title = "# The share of false loop closures, and what the odometry can tell"
    skipped, files, fractions, seeds = _bench.corrupted_plan(args, FILES, QUICK_FILES, FRACTIONS, args.share_seeds)
    if skipped:
        return f"{title}\n\n{skipped}"
    rows, summary, variant_rows = [], [], []
    for rel, graph in _bench.each_dataset(files):
        clean_chi2 = refine(graph, lago(graph).poses).chi2
        n_true = graph.n_loop_closures
        true_pass = int(np.sum(chain_consistency(graph, odometry_chain(graph), np.flatnonzero(~graph.is_odometric))
                               <= C2))
        for fraction in fractions:
            runs = []
            for seed in seeds:
                t = time.perf_counter()
                go, idx, clean_cost = corrupted(graph, fraction, seed)
                free = np.flatnonzero(~go.is_odometric)
                false = np.isin(free, idx)
                chain = odometry_chain(go)
                false_pass = int(np.sum(chain_consistency(go, chain, free)[false] <= C2))
                rates, clique = (float("nan"),) * 3, None
                if free.size <= PCM_MAX_EDGES:
                    d2 = pairwise_matrix(go, chain, free)
                    rates = pair_rates(d2, false, C2)
                    adj = d2 <= C2
                    np.fill_diagonal(adj, False)
                    clique = maximum_clique(adj, time_limit=RobustSettings().clique_seconds)
                s = score(graph, go, idx, lago(go, robust=True), clean_chi2, clean_cost)
                runs.append(dict(n_false=idx.size, share=idx.size / free.size, false_pass=false_pass, rates=rates, **s))
                rows.append([rel, f"{idx.size} ({fraction:.0%})", seed, f"{idx.size / free.size:.1%}",
                             f"{false_pass} of {idx.size}", *(_bench.fmt(x, ".1%") for x in rates),
                             "–" if clique is None else f"{clique.size} / {int(false[clique].sum())}",
                             f"{s['kept']} / {s['wrong']}", f"{s['gap']:.1f}", f"{s['ratio']:.4g}",
                             "yes" if s["ok"] else "no"])
                print(" | ".join(map(str, rows[-1])) + f"  ({time.perf_counter() - t:.1f} s)", flush=True)
            n_false, false_pass = runs[0]["n_false"], np.mean([r["false_pass"] for r in runs])
            summary.append([rel, graph.n_poses, n_true, f"{fraction:.0%}", n_false,
                            f"{np.mean([r['share'] for r in runs]):.1%}",
                            f"{true_pass} of {n_true} ({true_pass / n_true:.0%})",
                            f"{false_pass:.0f} of {n_false} ({false_pass / n_false:.0%})",
                            *(_bench.fmt(np.mean([r["rates"][i] for r in runs]), ".1%") for i in range(3)),
                            f"{sum(r['ok'] for r in runs)} of {len(runs)}"])
        if getattr(args, "share_variants", False) and not args.quick and rel == VARIANT_FILE:
            for seed in seeds:
                go, idx, clean_cost = corrupted(graph, VARIANT_FRACTION, seed)
                for name, settings in VARIANTS:
                    t = time.perf_counter()
                    res = lago(go, robust=settings)
                    seconds = time.perf_counter() - t
                    s = score(graph, go, idx, res, clean_chi2, clean_cost)
                    variant_rows.append([seed, name, f"{s['kept']} / {s['wrong']}", f"{s['gap']:.1f}",
                                         f"{s['ratio']:.4g}", "yes" if s["ok"] else "no", f"{seconds:.1f}"])
                    print("variant: " + " | ".join(map(str, variant_rows[-1])), flush=True)
    text = [title, "", __doc__.split("\n\n", 1)[1].strip(), "",
            "## Summary per file and fraction", "",
            "Means over the seeds; \"pairs\" columns: the share of consistent pairs of each kind (\"–\": more than "
            "1000 loop closures, no pairwise test, as in PCM).", "",
            _bench.table(["file", "poses", "true loop closures", "false edges", "false loop closures",
                          "false share of the loop closures", "true ones passing the single test",
                          "false ones passing it", "pairs true–true", "pairs true–false", "pairs false–false",
                          "robust LAGO passes"], summary),
            "", "## Every run", "",
            _bench.table(["file", "false edges", "seed", "false share of the loop closures",
                          "false passing the single test", "pairs true–true", "pairs true–false", "pairs false–false",
                          "maximum clique: size / false in it", "robust: false kept / true rejected",
                          "truncated cost, ours − clean", "χ² clean edges / clean χ²", "pass"], rows)]
    if variant_rows:
        text += ["", f"## Other searches on {VARIANT_FILE} + {VARIANT_FRACTION:.0%}", "",
                 "Each a `RobustSettings` of the package; the columns as above, seconds of the robust run.", "",
                 _bench.table(["seed", "settings", "false kept / true rejected", "truncated cost, ours − clean",
                               "χ² clean edges / clean χ²", "pass", "time [s]"], variant_rows)]
    return "\n".join(text)
