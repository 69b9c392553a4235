"""The options of ``--robust`` shared by ``solve`` and ``certify``, and the ``RobustSettings`` they ask for."""

from __future__ import annotations

import argparse
import math

from .common import UsageError, positive_float

THRESHOLD_HELP = ("with --robust (implies it): the truncation c̄² itself (whitened residual, squared) instead of "
                  "the χ² quantile of --robust-confidence (11.34 planar, 16.81 in 3-D); for files whose information "
                  "is loose for their residuals, see the c̄² windows of benchmarks/window.md")
CONFIDENCE_HELP = ("with --robust (implies it): c̄² = the χ² quantile at P of 3 (planar) or 6 (3-D) degrees of "
                   "freedom (default 0.99)")


def confidence_arg(value: str) -> float:
    """A number strictly between 0 and 1 (argparse type)."""
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {value!r}") from None
    if not (math.isfinite(v) and 0.0 < v < 1.0):
        raise argparse.ArgumentTypeError(f"expected a number strictly between 0 and 1, got {value!r}")
    return v


def add_robust_options(s, *, robust_help: str, calibrate: bool) -> None:
    """``--robust`` and the options that imply it: ``--robust-loss``, ``--robust-threshold``,
    ``--robust-confidence`` and (``calibrate``: ``solve`` only) ``--robust-calibrate``."""
    s.add_argument("--robust", action="store_true", help=robust_help)
    s.add_argument("--robust-loss", choices=["tls", "gm"], default=None,
                   help="the loss of --robust (implies it): tls, truncated least squares (default), or gm, "
                        "Geman-McClure")
    s.add_argument("--robust-threshold", type=positive_float, default=None, metavar="C2", help=THRESHOLD_HELP)
    s.add_argument("--robust-confidence", type=confidence_arg, default=None, metavar="P", help=CONFIDENCE_HELP)
    if calibrate:
        s.add_argument("--robust-calibrate", type=positive_float, default=None, metavar="K",
                       help="with --robust (implies it; planar): GNC again at c̄² = min(c̄², K × the largest r² "
                            "of the trusted odometric edges), the classification of the lower truncated cost at that "
                            "c̄² kept; 4.7 in benchmarks/separable.md")


def robust_request(args, dim: int):
    """The ``RobustSettings`` the command line asks for on a ``dim``-dimensional graph (None: not robust). Sets
    ``args.robust`` to the run's label ("gnc-tls" / "gnc-gm", or None) for the report. ``UsageError`` for
    ``--robust-threshold`` with ``--robust-confidence`` (one c̄² at a time) and for ``--robust-calibrate`` in 3-D."""
    calibrate = getattr(args, "robust_calibrate", None)
    implied = (args.robust_loss, args.robust_threshold, args.robust_confidence, calibrate)
    if not (args.robust or any(v is not None for v in implied)):
        args.robust = None
        return None
    if args.robust_threshold is not None and args.robust_confidence is not None:
        raise UsageError("--robust-threshold and --robust-confidence both set c̄² (the first directly, the second as "
                         "a χ² quantile): give one")
    if calibrate is not None and dim == 3:
        raise UsageError("--robust-calibrate: planar graphs only (a 3-D file's truncation is the χ² quantile of "
                         "6 dof; --robust-threshold sets it directly)")
    from ..variants import RobustSettings

    args.robust = f"gnc-{args.robust_loss or 'tls'}"
    given = dict(threshold=args.robust_threshold, confidence=args.robust_confidence, calibrate=calibrate)
    return RobustSettings(loss=args.robust_loss or "tls", **{k: v for k, v in given.items() if v is not None})
