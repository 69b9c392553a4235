# %% [markdown]
# # Lecture 6 — The experiment (the seed's Section V)
#
# The seed — Carlone, Aragues, Castellanos, Bona, *A Linear Approximation for Graph-based Simultaneous
# Localization and Mapping* (RSS 2011) — evaluates LAGO on one real graph, the Intel Research Lab
# data set (**INTEL**: 1228 poses, 1227 odometric edges, 278 loop closures). The file
# `../shared/datasets/carlone/INTEL_P_toro.graph` matches that description exactly (datasets README §1),
# so this lecture re-runs the experiment on it with `lago_cvx`:
#
# 1. **Table I** — the size of the graph and the number of chords that need a $2k\pi$ correction
#    (eqs. (20)–(23), Theorem 3) with the odometric spanning tree — reproduced exactly;
# 2. **Figure 1** — the odometric trajectory with the loop closures;
# 3. **Figure 2a** — the LAGO estimate (Figure 2b, the laser map, cannot be reproduced: no scans here);
# 4. **Figure 3** — cost of an iterative method versus iterations, with LAGO's level as a horizontal
#    line; and what the numbers say about LAGO's accuracy on this file (honestly: far from the optimum);
# 5. the same measurements on **eight more benchmark graphs**, as a table;
# 6. the same question on a **synthetic world with ground truth** (runs without the real data);
# 7. a side-by-side run of **GTSAM's LAGO** (`gtsam.lago.initialize`) when GTSAM is installed.
#
# **Cost.** Every cost printed is the χ² of eq. (3) in the g2o convention,
# $\chi^2 = \sum_{ij} e_{ij}^\top \Omega_{ij} e_{ij}$ with
# $e_{ij} = [R(\theta_i)^\top(p_j - p_i) - \Delta^l_{ij};\ \mathrm{wrap}(\theta_j - \theta_i - \delta_{ij})]$
# (no factor ½; `lago_cvx.cost.chi2`). **Iterative method.** The package's sparse Gauss–Newton
# (`lago_cvx.refine.refine`, `method="gauss-newton"`, backtracking line search when a full step would
# increase χ²) and Levenberg–Marquardt (`method="levenberg-marquardt"`); both minimise exactly this χ².
#
# Real-data cells print "real datasets not found: skipping …" when `../shared/datasets` is absent;
# the notebook then still runs top to bottom (section 6 needs no data).

# %%
import logging
import time
from dataclasses import replace

import matplotlib.pyplot as plt
import numpy as np

from _lecture import figure_saver, paper_lago
import lago_cvx as lc
from lago_cvx import peers, plotting
from lago_cvx.datasets import REFERENCE_CHI2, DatasetNotFound, dataset
from lago_cvx.posegraph import wrap_angle
from lago_cvx.metrics import ate
from lago_cvx.refinement import odometry_guess, refine

save = figure_saver("06")

T_START = time.perf_counter()

# The regularization logs a warning for every ambiguous chord (cycle residual near ±π). On MIT and
# M3500a with the odometric tree there are 4 and 58 of them; the tables below report their number,
# so the log lines are silenced here.
logging.getLogger("lago_cvx").setLevel(logging.ERROR)

def show_markdown(text):
    """Render a Markdown table in Jupyter; print it as text elsewhere."""
    try:
        from IPython import get_ipython
        from IPython.display import Markdown, display
        if get_ipython() is not None:
            display(Markdown(text))
            return
    except ImportError:
        pass
    print(text)


def load(rel):
    """Read a benchmark graph, or return None (and say so) when the datasets are absent."""
    try:
        return lc.read_graph(dataset(rel))
    except DatasetNotFound as exc:
        print(f"real datasets not found: skipping {rel} ({exc})")
        return None


def iterations_to_reach(result, target, rel=1e-3):
    """First iteration (log entry) whose χ² is within ``rel`` of ``target``, or None."""
    chi = np.array([e["chi2"] for e in result.log])
    hit = np.flatnonzero(chi <= (1.0 + rel) * target)
    return int(hit[0]) if hit.size else None


def wrapped_pose_difference(a, b):
    """max |Δx|, |Δy| and max |wrap(Δθ)| between two (n, 3) pose arrays."""
    d = np.asarray(a) - np.asarray(b)
    return float(np.abs(d[:, :2]).max()), float(np.abs(wrap_angle(d[:, 2])).max())


INTEL_REL = "carlone/INTEL_P_toro.graph"
INTEL = load(INTEL_REL)

# %% [markdown]
# ### Reference minima
#
# There is no published χ² minimum for these files in the g2o convention. The values below are the
# **"χ² min (from chordal/SE-Sync point)"** column of `../shared/datasets/README.md` §4.2
# ("Optimal costs computed here — UNCERTAIN (not published; local GN, not certified)"): Gauss–Newton on
# the g2o χ² started from the chordal/SE-Sync solution. They are the best minima known, not certified
# global optima. (The SE-Sync costs of §4.1 are certified, but they are a *different* objective and
# must not be compared with χ².) The same README also lists the χ² that plain GN reaches from the
# file's initial guess; two of them are local minima.

# %%
# datasets README §4.2, column "χ² min (from chordal/SE-Sync point)", as the package keeps it
CHI2_MIN = {rel: REFERENCE_CHI2[rel] for rel in (
    "se-sync/MIT.g2o", "carlone/FR079_P_toro.graph", "carlone/CSAIL_P_toro.graph", "se-sync/intel.g2o",
    "carlone/INTEL_P_toro.graph", "carlone/input_M3500_g2o.g2o", "carlone/input_M3500a_g2o.g2o",
    "carlone/M3500_P_toro.graph", "se-sync/city10000.g2o")}
# datasets README §4.2, column "χ² reached by GN from file init", where it is a local minimum
CHI2_GN_FROM_FILE_INIT_LOCAL = {"se-sync/MIT.g2o": 769.707, "carlone/input_M3500a_g2o.g2o": 6673.12}

# %% [markdown]
# ## 1. Table I — the INTEL graph and its regularization
#
# The seed's Table I describes INTEL by the number of poses, of odometric edges (between consecutive
# poses), of loop closures (all the other edges), and the number of chords whose relative orientation
# needs a non-zero $2k\pi$ correction when the cycle basis is built on the **odometric spanning tree**
# (the tree made of the odometric edges; each loop closure is then one chord, $l = m - n = 278$ here).
#
# Recall the regularization as formulated here (lecture on eqs. (20)–(23), `lago_cvx.regularization`):
# with $\theta^{\mathrm{tree}}$ the orientations integrated along the tree, chord $c = (i \to j)$ gets
# $k_c = -\mathrm{round}\big((C\delta)_c / 2\pi\big)$, $(C\delta)_c = \delta_c -
# (\theta^{\mathrm{tree}}_j - \theta^{\mathrm{tree}}_i)$. A chord "needs regularization" when $k_c \neq 0$;
# that count is `lago(graph, spanning_tree="odometry").regularization.n_regularized`.

# %%
TABLE_I_SEED = {"number of poses": 1228, "odometric edges": 1227, "loop closures": 278,
                "chords needing regularization (odometric tree)": 198}

if INTEL is None:
    print("real datasets not found: skipping Table I")
else:
    intel_odo = paper_lago(INTEL, spanning_tree="odometry")     # the seed's choice of tree
    intel_bfs = paper_lago(INTEL)                                # the package default (BFS tree)
    reg = intel_odo.regularization
    ours = {"number of poses": INTEL.n_poses, "odometric edges": INTEL.n_odometric,
            "loop closures": INTEL.n_loop_closures,
            "chords needing regularization (odometric tree)": reg.n_regularized}
    rows = ["| INTEL | seed, Table I | this file, `lago_cvx` |", "|---|---:|---:|"]
    rows += [f"| {k} | {TABLE_I_SEED[k]} | {ours[k]} |" for k in TABLE_I_SEED]
    show_markdown("\n".join(rows))
    for k in TABLE_I_SEED:
        assert ours[k] == TABLE_I_SEED[k], (k, ours[k], TABLE_I_SEED[k])
    # with the odometric tree every loop closure is a chord
    assert intel_odo.tree.n_chords == INTEL.n_loop_closures == INTEL.n_edges - INTEL.n_poses + 1
    print(f"chords {intel_odo.tree.n_chords}; k≠0 on {reg.n_regularized}; ambiguous (|residual| > π − "
          f"{reg.margin}) {reg.ambiguous.size}; largest |corrected cycle residual| "
          f"{np.abs(reg.residual).max():.3f} rad")
    print(f"distinct |k| values: {sorted(set(np.abs(reg.k_chords).tolist()))}")
    rb = intel_bfs.regularization
    print(f"for comparison, BFS (shortest-depth) tree: k≠0 on {rb.n_regularized} of {rb.chords.size} chords, "
          f"largest |residual| {np.abs(rb.residual).max():.3f} rad")
    assert reg.ambiguous.size == 0 and rb.ambiguous.size == 0

# %% [markdown]
# All four numbers of Table I are reproduced exactly; no chord is ambiguous (every corrected cycle
# residual is at least 0.96 rad away from ±π), so by Theorem 3 / Corollary 3 as formulated here the
# corrections are the ones that make every cycle consistent. The count depends on the tree: along
# the shortest-depth (BFS) tree the paths are shorter, accumulate less rotation, and only 52 chords need
# a correction — the *estimate* is the same (section 3).
#
# ## 2. Figure 1 — the odometric trajectory with the loop closures
#
# The odometric trajectory is dead reckoning: the odometric measurements composed from pose 0 (eq. (1)),
# `lago_cvx.refine.odometry_guess`. It is also what the file's `VERTEX2` lines hold — we check that.

# %%
if INTEL is None:
    print("real datasets not found: skipping Figure 1")
else:
    intel_dr = odometry_guess(INTEL)                        # dead reckoning along the odometric chain
    dxy, dth = wrapped_pose_difference(intel_dr, INTEL.initial)
    print(f"dead reckoning vs the file's VERTEX2 lines: max |Δx|,|Δy| = {dxy:.1e} m, max |Δθ| = {dth:.1e} rad "
          "(the file prints 6 decimals)")
    assert dxy < 1e-5 and dth < 1e-5
    chi2_dr = lc.chi2(INTEL, intel_dr)
    print(f"χ²(odometric trajectory) = {chi2_dr:.4g}  (datasets README §4.2: 5.834e6 at the file's init)")
    assert abs(chi2_dr - 5.834e6) < 1e-3 * 5.834e6

    fig, ax = plt.subplots(figsize=(7.5, 7.5))
    plotting.plot_edges(ax, INTEL, intel_dr, which="loop_closures", color="tab:red", linewidth=0.5,
                        alpha=0.7, label=f"loop closures ({INTEL.n_loop_closures})")
    plotting.plot_trajectory(ax, intel_dr, color="tab:blue", linewidth=0.9,
                             label=f"odometric trajectory ({INTEL.n_poses} poses)")
    ax.plot(*intel_dr[0, :2], "ko", markersize=6, label="pose 0 (anchor)")
    ax.set_title("Figure 1 — INTEL (INTEL_P_toro.graph): odometric trajectory\n"
                 "and loop closures drawn between the odometric positions")
    ax.legend(loc="best", fontsize=9)
    ax.grid(alpha=0.3)
    save(fig, "fig1_intel_odometry")
    plt.close(fig)

# %% [markdown]
# The loop closures join places the robot visited twice; drawn between the *odometric* positions they
# are long segments across the map — the accumulated drift that the optimisation has to remove.
#
# ## 3. Figure 2a — the LAGO estimate
#
# The seed builds its cycle basis on the odometric tree; the package's default is the shortest-depth
# (BFS) tree. When both trees yield correct $2k\pi$ corrections (no ambiguous chord, as on INTEL),
# the regularized orientations differ only by multiples of $2\pi$ per pose, so phase 1, 2 and 3 give
# the same positions and the same orientations modulo $2\pi$, hence the same χ². We check it and draw
# both, beside the refined optimum (Gauss–Newton from LAGO's estimate, section 4) for comparison.
#
# **Figure 2b** of the seed shows the laser scans rendered with the LAGO estimate (a map). The graph
# files here contain only poses and relative-pose measurements — **no laser scans** — so Figure 2b
# cannot be reproduced.

# %%
if INTEL is None:
    print("real datasets not found: skipping Figure 2a")
else:
    dxy, dth = wrapped_pose_difference(intel_odo.poses, intel_bfs.poses)
    print(f"LAGO, odometric tree vs BFS tree: max position difference {dxy:.1e} m, max wrapped θ difference "
          f"{dth:.1e} rad; unwrapped θ differ by up to {np.abs(intel_odo.poses[:, 2] - intel_bfs.poses[:, 2]).max() / (2 * np.pi):.0f}·2π")
    print(f"χ²(LAGO, odometric tree) = {intel_odo.chi2:.6f}")
    print(f"χ²(LAGO, BFS tree)       = {intel_bfs.chi2:.6f}")
    assert dxy < 1e-6 and dth < 1e-9
    assert abs(intel_odo.chi2 - intel_bfs.chi2) < 1e-9 * intel_bfs.chi2
    print(f"LAGO closed form on INTEL: {intel_odo.timings['total'] * 1e3:.0f} ms (odometric tree), "
          f"{intel_bfs.timings['total'] * 1e3:.0f} ms (BFS tree)")
    intel_opt = refine(INTEL, intel_odo.poses, method="gauss-newton")    # used for the third panel

    fig, axs = plt.subplots(1, 3, figsize=(17, 6.2))
    panels = [(intel_odo.poses, f"LAGO, odometric tree (the seed's)\nχ² = {intel_odo.chi2:.1f}"),
              (intel_bfs.poses, f"LAGO, BFS tree (package default)\nχ² = {intel_bfs.chi2:.1f}"),
              (intel_opt.poses, f"for comparison: Gauss–Newton from LAGO\n(optimum) χ² = {intel_opt.chi2:.3f}")]
    for ax, (poses, title) in zip(axs, panels):
        plotting.plot_edges(ax, INTEL, poses, which="loop_closures", color="tab:red", linewidth=0.5,
                            alpha=0.7, label="loop closures")
        plotting.plot_trajectory(ax, poses, color="tab:blue", linewidth=0.9, label="estimate")
        ax.set_title(title, fontsize=11)
        ax.grid(alpha=0.3)
    axs[0].legend(loc="lower left", fontsize=9)
    fig.suptitle("Figure 2a — INTEL: LAGO estimate with the loop closures "
                 "(Figure 2b, the laser map, is not reproducible: no scans in the data)", fontsize=12)
    fig.tight_layout()
    save(fig, "fig2a_intel_lago")
    plt.close(fig)

# %% [markdown]
# The two LAGO estimates coincide (to $10^{-9}$ in position; orientations equal modulo $2\pi$). At
# the scale of the map LAGO's trajectory looks like the optimum: the loop closures have become short
# segments. The χ² values say otherwise — see the next section.
#
# ## 4. Figure 3 — an iterative method versus iterations, and LAGO's level
#
# The seed's Figure 3 plots the error of an iterative solver against the iteration count and marks
# the level of LAGO's (non-iterative) estimate by a horizontal line, so one reads off how many
# iterations the iterative method needs to reach LAGO's level. Its error metric and its iterative
# methods (TORO-style) differ from what this package has, so **our Figure 3 is a qualitative
# counterpart**, not a reproduction:
#
# * metric: the g2o χ² of eq. (3) defined above, log scale;
# * iterative methods: the package's Gauss–Newton and Levenberg–Marquardt (`lago_cvx.refine`), started
#   from the odometric trajectory (Figure 1), and Gauss–Newton started from LAGO's estimate;
# * horizontal lines: χ²(LAGO) (dashed black) and the reference minimum 213.212 (datasets README §4.2,
#   dashed grey).
#
# One Levenberg–Marquardt *trial* (accepted or rejected) costs one sparse factorisation, like one
# Gauss–Newton iteration, so LM is plotted per trial.

# %%
if INTEL is None:
    print("real datasets not found: skipping Figure 3")
else:
    ref = CHI2_MIN[INTEL_REL]
    t = time.perf_counter()
    gn_dr = refine(INTEL, intel_dr, method="gauss-newton", max_iterations=50)
    t_gn_dr = time.perf_counter() - t
    t = time.perf_counter()
    lm_dr = refine(INTEL, intel_dr, method="levenberg-marquardt", max_iterations=500)
    t_lm_dr = time.perf_counter() - t
    t = time.perf_counter()
    gn_lago = refine(INTEL, intel_odo.poses, method="gauss-newton", max_iterations=50)
    t_gn_lago = time.perf_counter() - t
    runs = [("GN from odometry", gn_dr, t_gn_dr), ("LM from odometry", lm_dr, t_lm_dr),
            ("GN from LAGO", gn_lago, t_gn_lago)]
    print(f"{'run':18s} {'χ² start':>11s} {'χ² end':>10s} {'accepted steps':>15s} {'log entries':>12s} "
          f"{'to ≤ χ²(LAGO)':>14s} {'to ≤ 1.001·min':>15s} {'time':>8s}  reason")
    for name, r, dt in runs:
        below_lago = iterations_to_reach(r, intel_odo.chi2, rel=0.0)
        print(f"{name:18s} {r.chi2_initial:11.5g} {r.chi2:10.4f} {r.iterations:15d} {len(r.log) - 1:12d} "
              f"{str(below_lago):>14s} {str(iterations_to_reach(r, ref)):>15s} {dt:7.2f}s  {r.reason}")
        assert r.converged and abs(r.chi2 - ref) < 1e-3 * ref

    fig, axs = plt.subplots(1, 2, figsize=(15, 5.8))
    for ax, last in zip(axs, (25, None)):
        for (name, r, _), color in zip(runs, ("tab:blue", "tab:orange", "tab:green")):
            values = [e["chi2"] for e in r.log][:None if last is None else last + 1]
            plotting.plot_convergence(ax, values, label=f"{name} ({len(r.log) - 1} {'trials' if 'LM' in name else 'iterations'})",
                                      color=color)
        plotting.plot_convergence(ax, [], reference=intel_odo.chi2,
                                  reference_label=f"LAGO, χ² = {intel_odo.chi2:.0f}")
        ax.axhline(ref, linestyle="--", color="0.55", linewidth=1.2,
                   label=f"reference minimum, χ² = {ref} (datasets README 4.2)")
        ax.set_xlabel("iteration (GN) / trial (LM)")
        ax.grid(alpha=0.3, which="both")
    axs[0].set_xlim(-0.5, 25.5)
    axs[0].set_title("first 25 iterations")
    axs[1].set_title(f"whole runs (LM needs {len(lm_dr.log) - 1} trials)")
    axs[0].legend(fontsize=9, loc="upper right")
    fig.suptitle("Figure 3 — INTEL: χ² (g2o convention, eq. (3)) of iterative methods vs iterations, "
                 "with LAGO's level", fontsize=12)
    fig.tight_layout()
    save(fig, "fig3_intel_convergence")
    plt.close(fig)

# %% [markdown]
# ### What Figure 3 says
#
# The numbers, measured in the cell below:
#
# * **LAGO is not close to the optimum on this file in the χ² metric.** χ²(LAGO) ≈ 16 598 against the
#   reference minimum 213.212: a ratio of about 78. The claim (as this project's brief summarises the
#   seed) that the LAGO estimate often makes a nonlinear refinement unnecessary does **not** hold on
#   INTEL_P_toro.graph when accuracy is measured by χ². Where the excess sits is printed below: the
#   rotational part of eq. (3) at LAGO's estimate equals the optimum's to 0.1 % (190.1 vs 189.9) and
#   the orientations differ by at most 0.08 rad, while the translational part is 16 408 against 23.3 —
#   the positions carry the error (phase 3 linearises the position errors around phase 1's θ̂). On
#   the map (Figure 2a) the position differences are at most 1.8 m. *Why* is measured in the cell after
#   the next one: it is phase 3 itself.
# * **LAGO is an excellent initial guess.** Gauss–Newton from LAGO reaches the minimum within 0.1 % in
#   2 iterations and stops (converged) after 4; from the odometric trajectory GN needs 8 iterations,
#   with a backtracking line search in its first 5 (the full step would have increased χ²), and
#   Levenberg–Marquardt needs hundreds of trials. In the seed's spirit: started from odometry, GN needs
#   7 iterations and LM 126 trials just to get *down to LAGO's level* (the crossing of the black
#   line), while LAGO costs one sparse factorisation per linear phase.
# * On INTEL, GN from odometry is not trapped: all three runs end at the same minimum 213.212
#   (the datasets README found the same). Section 5 shows graphs where odometry *is* a trap.

# %%
if INTEL is None:
    print("real datasets not found: skipping the Figure 3 numbers")
else:
    ratio = intel_odo.chi2 / ref
    print(f"χ²(LAGO) = {intel_odo.chi2:.1f}, reference minimum = {ref}, ratio = {ratio:.1f}")
    assert 70 < ratio < 90                                   # LAGO is ~78x above the optimum here
    parts_lago = lc.chi2_parts(INTEL, intel_odo.poses)
    parts_opt = lc.chi2_parts(INTEL, gn_lago.poses)
    for name, p in (("LAGO", parts_lago), ("optimum", parts_opt)):
        print(f"  {name:8s} translation {p['translation']:10.1f}  rotation {p['rotation']:8.1f}  "
              f"cross {p['cross']:8.1f}  total {p['chi2']:10.1f}")
    dxy, dth = wrapped_pose_difference(intel_odo.poses, gn_lago.poses)
    print(f"LAGO vs optimum (same anchor): max position difference {dxy:.3f} m, max orientation difference "
          f"{dth:.4f} rad")
    assert dxy < 2.0 and dth < 0.1
    print(f"GN from LAGO: {gn_lago.iterations} iterations, within 0.1 % of the minimum after "
          f"{iterations_to_reach(gn_lago, ref)}; GN from odometry: {gn_dr.iterations} iterations, "
          f"within 0.1 % after {iterations_to_reach(gn_dr, ref)}; halvings per GN-from-odometry iteration: "
          f"{[e['halvings'] for e in gn_dr.log[1:]]}")
    print(f"LM from odometry: {lm_dr.iterations} accepted steps in {len(lm_dr.log) - 1} trials")
    assert iterations_to_reach(gn_lago, ref) <= 3 and gn_lago.iterations <= 8
    assert iterations_to_reach(gn_dr, ref) > iterations_to_reach(gn_lago, ref)
    assert iterations_to_reach(gn_dr, intel_odo.chi2, rel=0.0) >= 5   # GN needs ≥ 5 iterations to beat LAGO
    assert iterations_to_reach(lm_dr, intel_odo.chi2, rel=0.0) >= 100 and len(lm_dr.log) - 1 > 100
    # the excess of LAGO's χ² is translational: its rotational part is that of the optimum (±1 %)
    assert abs(parts_lago["rotation"] - parts_opt["rotation"]) < 0.01 * parts_opt["rotation"]
    assert parts_lago["translation"] > 100 * parts_opt["translation"]

# %% [markdown]
# ### Where the 78× comes from: Theorem 1, measured
#
# Theorem 1 (the three phases approximate the solution of eq. (6); phase 3 corrects the sub-optimal
# estimate $\hat x = [\hat p; \hat\theta]$ "towards a minimum") rests on two statements:
# the **identity** $x^* = \hat x + [\tilde\rho; \tilde\delta]$ with the corrections of eqs. (16)–(17),
# and the **claim** that this lowers the cost. `lago_cvx.theorem1` measures both: $\hat p$ is eq. (14)
# (the positions that minimise the cost with $\hat\theta$ fixed), the corrections come from block
# elimination of phase 3's normal equations. On INTEL the identity holds to rounding, but the claim does
# not: $\chi^2(\hat x)$ is within 2 % of the minimum and phase 3 moves it to $\chi^2(x^*)$ ≈ 78× the
# minimum. Phase 3 is one Gauss–Newton step of the linearisation (18); INTEL's translational information
# reaches $10^8$ (σ ≈ 0.1 mm on some edges), so the position residuals left at $\hat x$ by ordinary
# orientation noise dominate the step, and the linear model asks for orientation changes far larger
# than $\hat\theta$'s error (here in a direction that moves *away* from the optimum's orientations).
# Re-solving the positions exactly for the orientations (`lago(..., positions="resolve")`, the package's
# default route) brings χ² back to within 0.3 % of the minimum.

# %%
if INTEL is not None:
    from lago_cvx.theorem1 import theorem1

    t1 = theorem1(INTEL, route="seed")
    default = lc.lago(INTEL)
    print(f"identity x* = x̂ + [ρ̃; δ̃] of eqs. (16)–(17): relative error {t1.identity_error:.1e}")
    print(f"χ² at x̂ (eq. (14) positions for θ̂) {t1.chi2_suboptimal:.1f} ({t1.chi2_suboptimal / ref:.3f}× the minimum); "
          f"at phase 3's x* {t1.chi2_phase3:.1f} ({t1.chi2_phase3 / ref:.1f}×); positions re-solved for θ* "
          f"{t1.chi2_resolved:.2f} ({t1.chi2_resolved / ref:.4f}×)")
    print(f"the package's default route: χ² {default.chi2:.2f} ({default.chi2 / ref:.4f}× the minimum)")
    assert t1.identity_error < 1e-9 and t1.chi2_phase3 > 50 * t1.chi2_suboptimal
    assert t1.chi2_suboptimal < 1.03 * ref and default.chi2 < 1.01 * ref

# %% [markdown]
# ## 5. The other benchmark graphs
#
# The same measurements on nine files (INTEL included): χ² of LAGO with the seed's odometric tree and
# with the package's default BFS tree, against the reference minimum (the dict `CHI2_MIN` above), and
# Gauss–Newton (`refine`, `max_iterations=50`, tolerance $10^{-9}$ on the relative χ² decrease) started from
# * LAGO (BFS tree) — the package's recommended pipeline,
# * LAGO (odometric tree) — the seed's,
# * the odometric trajectory, `odometry_guess(graph)` (dead reckoning along the odometric chain).
#
# "it." = accepted Gauss–Newton steps until the convergence test stopped it; "0.1 %" = the first
# iteration whose χ² is within 0.1 % of the reference minimum ("–" if never). All the runs converged
# within the 50-iteration bound (asserted), so the bound does not truncate any of them.

# %%
FILES = ["se-sync/MIT.g2o", "carlone/FR079_P_toro.graph", "carlone/CSAIL_P_toro.graph", "se-sync/intel.g2o",
         "carlone/INTEL_P_toro.graph", "carlone/input_M3500_g2o.g2o", "carlone/input_M3500a_g2o.g2o",
         "carlone/M3500_P_toro.graph", "se-sync/city10000.g2o"]
rows = {}
t_section = time.perf_counter()
for rel in FILES:
    g = INTEL if rel == INTEL_REL else load(rel)
    if g is None:
        continue
    row = {"n": g.n_poses, "m": g.n_edges, "min": CHI2_MIN[rel]}
    t = time.perf_counter()
    res_bfs = paper_lago(g)
    row["t_lago"] = time.perf_counter() - t
    res_odo = paper_lago(g, spanning_tree="odometry")
    row["lago_bfs"], row["lago_odo"] = res_bfs.chi2, res_odo.chi2
    row["amb_odo"] = res_odo.regularization.ambiguous.size
    dr = odometry_guess(g)
    row["dr"] = lc.chi2(g, dr)
    row["file_init"] = None if g.initial is None else lc.chi2(g, g.initial)
    for key, start in (("gn_bfs", res_bfs.poses), ("gn_odo", res_odo.poses), ("gn_dr", dr)):
        t = time.perf_counter()
        r = refine(g, start, method="gauss-newton", max_iterations=50)
        row[key] = (r.chi2, r.iterations, iterations_to_reach(r, CHI2_MIN[rel]), time.perf_counter() - t)
        assert r.converged, (rel, key, r.reason)
    rows[rel] = row
    print(f"{rel:32s} done ({time.perf_counter() - t_section:5.1f} s so far)")


def fmt_gn(cell, ref):
    chi, it, hit, _ = cell
    return f"{chi:.6g} ({chi / ref:.3g}×) | {it} | {'–' if hit is None else hit}"


if rows:
    lines = ["| file | poses | χ² min (README 4.2) | χ² LAGO odometric tree (×min) | χ² LAGO BFS (×min) "
             "| GN from LAGO-BFS: χ² | it. | 0.1 % | GN from LAGO-odometric: χ² | it. | 0.1 % "
             "| GN from odometry: χ² | it. | 0.1 % |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for rel, r in rows.items():
        amb = f", {r['amb_odo']} ambiguous" if r["amb_odo"] else ""
        lines.append(f"| {rel} | {r['n']} | {r['min']} | {r['lago_odo']:.6g} ({r['lago_odo'] / r['min']:.3g}×{amb}) "
                     f"| {r['lago_bfs']:.6g} ({r['lago_bfs'] / r['min']:.3g}×) | {fmt_gn(r['gn_bfs'], r['min'])} "
                     f"| {fmt_gn(r['gn_odo'], r['min'])} | {fmt_gn(r['gn_dr'], r['min'])} |")
    show_markdown("\n".join(lines))
    print("times (s): LAGO closed form (BFS) / GN from LAGO-BFS / GN from LAGO-odometric / GN from odometry")
    for rel, r in rows.items():
        print(f"  {rel:32s} {r['t_lago']:6.3f} / {r['gn_bfs'][3]:6.2f} / {r['gn_odo'][3]:6.2f} / {r['gn_dr'][3]:6.2f}")
    print(f"section 5 took {time.perf_counter() - t_section:.1f} s")
else:
    print("real datasets not found: skipping the table of benchmark graphs")

# %% [markdown]
# ### Checks
#
# 1. From LAGO with the BFS tree, Gauss–Newton reaches the reference minimum within 0.1 % in at most
#    8 iterations on every file — and it converges there (no local minimum).
# 2. From the odometric trajectory, Gauss–Newton ends in a local minimum on MIT (≈ 769.7, the value the
#    datasets README reports too) and on M3500a (≈ 7606 with this package's safeguarded GN — the
#    README's 6673.12 was found with plain, unsafeguarded GN steps, which take a different path); both
#    are more than 5× above the minimum. On the other seven files it reaches the minimum.
# 3. The tree matters for LAGO: with the seed's odometric tree, MIT and M3500a have ambiguous chords,
#    the $2k\pi$ corrections go wrong, LAGO lands hundreds (MIT) or tens (M3500a) of times above the
#    minimum, and GN from there also stops in a local minimum.

# %%
if rows:
    for rel, r in rows.items():
        chi, it, hit, _ = r["gn_bfs"]
        assert abs(chi - r["min"]) <= 1e-3 * r["min"] and hit is not None and hit <= 8 and it <= 8, (rel, r["gn_bfs"])
    print("check 1 passed: GN from LAGO (BFS) within 0.1 % of the minimum in ≤ 8 iterations on all "
          f"{len(rows)} files (worst: {max(r['gn_bfs'][2] for r in rows.values())} iterations)")
    for rel in ("se-sync/MIT.g2o", "carlone/input_M3500a_g2o.g2o"):
        if rel in rows:
            chi = rows[rel]["gn_dr"][0]
            print(f"check 2: {rel}: GN from odometry ends at {chi:.6g} = {chi / CHI2_MIN[rel]:.1f}× the minimum "
                  f"(README, plain GN from the file's init: {CHI2_GN_FROM_FILE_INIT_LOCAL[rel]})")
            assert chi > 5 * CHI2_MIN[rel]
            lago_odo_gn = rows[rel]["gn_odo"][0]
            print(f"check 3: {rel}: odometric-tree LAGO {rows[rel]['lago_odo']:.6g} "
                  f"({rows[rel]['amb_odo']} ambiguous chords) → GN {lago_odo_gn:.6g} = "
                  f"{lago_odo_gn / CHI2_MIN[rel]:.1f}× the minimum")
            assert rows[rel]["amb_odo"] > 0 and lago_odo_gn > 5 * CHI2_MIN[rel]
    if "se-sync/MIT.g2o" in rows:
        assert abs(rows["se-sync/MIT.g2o"]["gn_dr"][0] - 769.707) < 1e-3 * 769.707
    others = [rel for rel in rows if rel not in CHI2_GN_FROM_FILE_INIT_LOCAL]
    for rel in others:
        assert abs(rows[rel]["gn_dr"][0] - rows[rel]["min"]) <= 1e-3 * rows[rel]["min"], rel
    print(f"GN from odometry reaches the minimum on the other {len(others)} files")
    for rel, r in rows.items():
        if r["file_init"] is not None and abs(r["file_init"] - r["dr"]) > 1e-3 * r["dr"]:
            print(f"note: {rel}: the file's VERTEX lines are NOT dead reckoning: χ² {r['file_init']:.6g} "
                  f"at the file's poses vs {r['dr']:.6g} at odometry_guess")
else:
    print("real datasets not found: skipping the checks of section 5")

# %% [markdown]
# Reading the table:
#
# * **The paper's LAGO** (BFS tree) is within 3 % of the minimum on six of the nine files (FR079,
#   intel-1728, the three M3500 variants, city10000; ratios 1.0001–1.028) — on those, the suggestion
#   that refinement is often unnecessary is a fair summary. On INTEL (78×), CSAIL (8×) and MIT (6.7×) it
#   is far above, and the cause is phase 3's step, not the orientations: the sub-optimal estimate of
#   eq. (14) is 1.02×, 1.05× and 1.2× there (section 4 and `python benchmarks/run.py theorem1`). With
#   the positions re-solved exactly for the orientations — the package's default route — every one of
#   the nine is within 1 % but CSAIL (1.04×) and MIT (1.01×).
# * **As an initial guess** LAGO (BFS tree) is reliable on all nine: GN converges to the reference
#   minimum in 3–7 iterations. Dead reckoning fails on MIT and M3500a, and LAGO with the seed's
#   odometric tree fails on the same two.
# * `se-sync/intel.g2o` ships VERTEX lines that are not dead reckoning (χ² 549 at the file's poses —
#   the README's "χ² at file init" — against 5.6e4 at `odometry_guess`; the note printed above); the
#   table uses `odometry_guess` for every file.
#
# These statements are checked by the next cell.
#
# %%
if rows:
    close = sorted(rel for rel, r in rows.items() if r["lago_bfs"] < 1.03 * r["min"])
    far = sorted(rel for rel, r in rows.items() if r["lago_bfs"] > 5 * r["min"])
    print("LAGO (BFS) within 3 % of the minimum:", close)
    print("LAGO (BFS) more than 5× above the minimum:", far)
    its = [r["gn_bfs"][1] for r in rows.values()]
    print(f"GN iterations from LAGO (BFS): {min(its)}–{max(its)}")
    if len(rows) == len(FILES):
        assert len(close) == 6
        assert far == sorted(["carlone/INTEL_P_toro.graph", "carlone/CSAIL_P_toro.graph", "se-sync/MIT.g2o"])
        assert (min(its), max(its)) == (3, 7)
else:
    print("real datasets not found: skipping")

# %% [markdown]
# ## 6. The same question on a synthetic world with ground truth
#
# Real benchmark graphs have no ground truth; a seeded synthetic Manhattan world has
# (`lago_cvx.synthetic.manhattan_world`, 1000 poses, seed 1, σ_xy = 0.05, σ_θ = 0.1 rad). Here we can
# also measure the absolute trajectory error (ATE, RMS position error after the best rigid alignment,
# `lago_cvx.refine.ate`). This cell needs no data files.

# %%
world = lc.manhattan_world(1000, seed=1, sigma_theta=0.1)
g = world.graph
syn_lago = paper_lago(g)
syn_dr = odometry_guess(g)
syn_gn_lago = refine(g, syn_lago.poses)
syn_gn_dr = refine(g, syn_dr)
print(f"{g.n_poses} poses, {g.n_edges} edges ({g.n_loop_closures} loop closures)")
print(f"{'estimate':28s} {'χ²':>10s} {'ATE [m]':>8s}")
for name, poses, chi in (("ground truth", world.truth, lc.chi2(g, world.truth)),
                         ("odometry (dead reckoning)", syn_dr, lc.chi2(g, syn_dr)),
                         ("LAGO", syn_lago.poses, syn_lago.chi2),
                         (f"GN from LAGO ({syn_gn_lago.iterations} it.)", syn_gn_lago.poses, syn_gn_lago.chi2),
                         (f"GN from odometry ({syn_gn_dr.iterations} it.)", syn_gn_dr.poses, syn_gn_dr.chi2)):
    print(f"{name:28s} {chi:10.2f} {ate(poses, world.truth):8.3f}")
assert syn_gn_lago.converged and syn_gn_dr.converged
assert syn_lago.chi2 < 1.5 * syn_gn_lago.chi2                     # LAGO within 50 % of its refined minimum
assert syn_gn_dr.chi2 > 2 * syn_gn_lago.chi2                      # GN from odometry: a local minimum
assert ate(syn_lago.poses, world.truth) < ate(syn_dr, world.truth) / 10
assert ate(syn_gn_lago.poses, world.truth) < ate(syn_gn_dr.poses, world.truth)

# %% [markdown]
# The same picture as on MIT and M3500a: with σ_θ = 0.1 rad of odometric rotation noise, Gauss–Newton
# from dead reckoning stops in a local minimum; from LAGO it reaches a much lower minimum, whose
# trajectory is also the closest to the truth. LAGO alone is within some tens of per cent of that
# minimum in χ² (the truth itself has a *higher* χ² than the minimum — the estimate fits the noise).
#
# ## 7. Side by side with GTSAM's LAGO
#
# GTSAM ships LAGO as `gtsam.lago.initialize` (optional extra; `lago_cvx.peers.gtsam_lago`). GTSAM's
# between factors take diagonal noise models, so it is given the marginal standard deviations of each
# edge (cross terms dropped, `lago_cvx/peers.py`), and with `useOdometricPath=True` (its default) it
# uses the odometric tree — we compare with our odometric-tree LAGO. Only `gtsam.lago.initialize` is
# timed; our time is the median of 5 closed-form runs.

# %%
if not peers.have_gtsam():
    print("GTSAM is not installed (pip install 'lago-cvx[gtsam]'): skipping the GTSAM comparison")
elif INTEL is None:
    print("real datasets not found: skipping the GTSAM comparison")
else:
    times = []
    for _ in range(5):
        t = time.perf_counter()
        ours_poses = paper_lago(INTEL, spanning_tree="odometry").poses
        times.append(time.perf_counter() - t)
    theirs, t_theirs = peers.gtsam_lago(INTEL, odometric_path=True, repeat=5)
    chi_ours, chi_theirs = lc.chi2(INTEL, ours_poses), lc.chi2(INTEL, theirs)
    dxy, dth = wrapped_pose_difference(ours_poses, theirs)
    print(f"INTEL   lago_cvx: χ² = {chi_ours:10.1f}   time {np.median(times) * 1e3:5.1f} ms")
    print(f"INTEL   GTSAM   : χ² = {chi_theirs:10.1f}   time {t_theirs * 1e3:5.1f} ms")
    print(f"max position difference {dxy:.3f} m, max orientation difference {dth:.4f} rad")
    print(f"GN from GTSAM's estimate: χ² {refine(INTEL, theirs).chi2:.3f}")

    # Where the difference comes from: the same graph with isotropic translational noise
    cov = INTEL.covariance
    iso = np.zeros_like(INTEL.information)
    iso[:, 0, 0] = iso[:, 1, 1] = 2.0 / (cov[:, 0, 0] + cov[:, 1, 1])
    iso[:, 2, 2] = 1.0 / cov[:, 2, 2]
    INTEL_iso = replace(INTEL, information=iso)
    a = paper_lago(INTEL_iso, spanning_tree="odometry").chi2
    b = lc.chi2(INTEL_iso, peers.gtsam_lago(INTEL_iso)[0])
    print(f"INTEL with isotropic σ_x = σ_y per edge: χ² lago_cvx {a:.9g}, GTSAM {b:.9g}, "
          f"relative difference {abs(a - b) / b:.1e}")
    assert abs(a - b) < 1e-6 * b                      # same problem, same estimate
    sx, sy = np.sqrt(cov[:, 0, 0]), np.sqrt(cov[:, 1, 1])
    print(f"INTEL's own translational noise is anisotropic: σ_x/σ_y median {np.median(sx / sy):.1f}, "
          f"range {np.min(sx / sy):.2g} … {np.max(sx / sy):.3g}")
    assert chi_theirs > chi_ours

# %% [markdown]
# With isotropic translational noise GTSAM and `lago_cvx` give the same estimate (χ² equal to about
# $10^{-12}$), as `tests/test_gtsam.py` also checks on the diagonal-information files M3500 and
# city10000. On INTEL's anisotropic noise they differ. Reading GTSAM's source (`gtsam/slam/lago.cpp`,
# `computePoses`), its final linear solve writes each relative position in the **global** frame,
# $R(\hat\theta_i)\Delta^l_{ij}$, but whitens that residual with the edge's diagonal noise model,
# which is defined in the frame of the tail pose $i$; the seed's eq. (10) rotates $P_\Delta$ by
# $R(\hat\theta_i)$ as well, which is what phase 2 of `lago_cvx` does. This is our reading of the
# source, consistent with the isotropic check above; it is GTSAM's implementation choice, not
# something this notebook can attribute to the seed.
#
# ## Summary
#
# * Table I is reproduced exactly on `INTEL_P_toro.graph`: 1228 poses, 1227 odometric edges, 278 loop
#   closures, 198 chords with $k \ne 0$ along the odometric tree.
# * Figures 1 and 2a are reproduced in content (trajectory and loop closures before and after LAGO);
#   Figure 2b is not reproducible (no laser scans); Figure 3 is a qualitative counterpart.
# * In the χ² metric, the paper's LAGO is ~78× above the best known minimum on INTEL — there it is not
#   a substitute for refinement — while it is within 3 % on six of the nine benchmark graphs. The excess
#   is phase 3's overshoot (Theorem 1's identity holds, its claim does not); re-solving the positions for
#   the orientations (the default route) brings INTEL to 1.002×. As an initial guess (BFS tree) it is excellent everywhere: Gauss–Newton reaches the
#   minimum in ≤ 8 iterations, where dead reckoning (and LAGO with the seed's odometric tree) end in
#   local minima on MIT and M3500a.

# %%
elapsed = time.perf_counter() - T_START
print(f"lecture 6 executed in {elapsed:.1f} s")
