"""Seeded synthetic pose-graph worlds with ground truth.

These are the project's embedded data: demos and most tests run on them, so no real dataset is
needed. Every generator

* takes a ``seed`` and draws all randomness from one ``np.random.default_rng(seed)``, so the same
  arguments give bit-identical arrays (on the same NumPy version);
* is vectorized (the Manhattan random walk composes pre-drawn turns by cumulative sums, block by
  block, resolving only the steps that would leave the square one by one; loop-closure search uses
  ``scipy.spatial.cKDTree``, or one sort when only revisits of the same grid point qualify), so a
  million poses build in a few seconds;
* returns a :class:`SyntheticWorld`: the :class:`~lago_cvx.posegraph.PoseGraph` (measurements as a
  real front end would report them) plus the true poses and the generator parameters.

Measurement conventions (shared by all generators, see :func:`add_noise`)
-----------------------------------------------------------------------
An edge ``i → j`` (tail ``i``, head ``j``) measures pose ``j`` in the frame of pose ``i``:
``z = between(truth[i], truth[j]) + n`` with ``n ~ N(0, Σ)`` added to ``(Δx, Δy, δ)`` in the frame of
the tail, and the orientation ``δ`` is then **wrapped to [−π, π)** — for odometry and loop closures
alike, exactly like a real sensor. (The true unwrapped θ_j − θ_i of a loop closure can be e.g.
4π + π/2; only its wrapped value is stored. This is what makes LAGO's 2kπ regularization
necessary.) The information matrix is ``Ω = Σ_info⁻¹``:

* ``information="diagonal"`` (default): ``Ω = diag(1/σx², 1/σx², 1/σθ²)``;
* ``information="full"``: each edge gets its own seeded random correlation matrix ``C`` (all
  cross terms x–y, x–θ, y–θ non-zero) and ``Σ = S C S`` with ``S = diag(σx, σx, σθ)``; the noise is
  drawn with exactly that covariance.

The information uses ``info_sigma_xy`` / ``info_sigma_theta``, which default to the noise sigmas.
A noiseless world (``sigma_xy=0`` and/or ``sigma_theta=0``, giving *exactly* noiseless
measurements) still needs finite information: the reference sigmas :data:`REFERENCE_SIGMA_XY` =
0.05 and :data:`REFERENCE_SIGMA_THETA` = 0.02 are used then. The standardized noise draws do not
depend on the sigmas, so worlds that differ only in their sigmas have the same graph and noise
scaled proportionally.

``graph.initial`` is the dead-reckoning guess: the noisy (wrapped) measurements of a spanning path
or tree composed from the true pose of its root — exactly what a real dataset's VERTEX lines look
like. Edge order: the odometric chain ``i → i+1`` first (``edges 0 … n−2``), then the loop closures
sorted by (head, tail); :func:`random_graph` shuffles its edges.

``params`` always holds every generator argument (defaults resolved), ``"generator"``, and the
edge-index arrays ``"outliers"`` (false loop closures, see ``outlier_fraction``) and
``"loop_closures"`` (for :func:`random_graph`: the non-spanning edges, plus ``"spanning_edges"``).
"""

from .noise import (OUTLIER_MIN_CHI2, REFERENCE_SIGMA_THETA, REFERENCE_SIGMA_XY, SyntheticWorld, add_noise,
                    dead_reckoning)
from .outliers import FALSE_LOOP_BOX, add_false_loop_closures
from .worlds import circle_world, manhattan_world, random_graph

__all__ = ["SyntheticWorld", "manhattan_world", "circle_world", "random_graph", "add_noise", "dead_reckoning",
           "REFERENCE_SIGMA_XY", "REFERENCE_SIGMA_THETA", "OUTLIER_MIN_CHI2",
           "add_false_loop_closures", "FALSE_LOOP_BOX"]
