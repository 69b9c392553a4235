"""The g2o and TORO text formats of planar pose graphs: their record types and the TORO ↔ g2o
conversion of the information matrices. Reading is ``reader.py``, writing ``writer.py``.

Formats
=======
Both formats are line based: one record per line, whitespace-separated tokens (spaces or tabs; LF or
CRLF line ends). Blank lines and lines whose first non-blank character is ``#`` are skipped. Pose ids
are integers; they need not be contiguous or start at 0 (``PoseGraph.ids`` keeps them, sorted, and
edge endpoints become indices into it).

**g2o** (``VERTEX_SE2`` / ``EDGE_SE2``)::

    VERTEX_SE2 id x y θ
    EDGE_SE2   i j dx dy dθ I11 I12 I13 I22 I23 I33

The edge carries pose j measured in the frame of pose i and the *upper triangle* (row-major, order
x, y, θ) of the 3×3 information matrix Ω of the error ``e = [R_iᵀ(p_j − p_i) − Δˡ ; θ_j − θ_i − δ]``
— the convention of :mod:`lago_cvx.posegraph`. ``FIX id [id ...]`` lines are legal g2o; they are
validated (integer ids), logged at INFO level and otherwise ignored (LAGO picks its own anchor).

**TORO / HOG-Man** (``VERTEX2`` / ``EDGE2``)::

    VERTEX2 id x y θ
    EDGE2   i j dx dy dθ Ixx Ixy Iyy Iθθ Ixθ Iyθ

Same measurement, but the six information entries come in a different order (HOG-Man's
``inf_ff inf_fs inf_ss inf_rr inf_fr inf_sr``; in error messages the fields are called
``Ixx Ixy Iyy Itt Ixt Iyt``, t standing for θ) **and in a different frame**.

TORO → g2o information conversion
---------------------------------
A TORO information matrix Ω_toro is converted on reading to the g2o convention by

    Ω_g2o = Tᵀ Ω_toro T,    T = blkdiag(R(dθ), 1),

where R(dθ) is the 2-D rotation by the edge's *own* measured angle dθ. This rotates the 2×2
translational block (R(dθ)ᵀ Ω_tt R(dθ)) and the x-θ / y-θ cross terms consistently; Ω_θθ is unchanged.
Writing TORO applies the inverse, Ω_toro = T Ω_g2o Tᵀ (T is orthogonal). The rotation and its
direction are an empirical convention, fixed by the data below rather than derived from TORO's code.

Evidence (datasets README §2.3, re-checked by ``tests/test_io.py``): SE-Sync's ``manhattan.g2o`` and
``CSAIL.g2o`` were produced from Carlone's ``M3500_P_toro.graph`` and ``CSAIL_P_toro.graph``. The twins
have the same endpoints and measurements, and after this conversion *every* edge's information agrees
to 1e-4 relative (the g2o files were printed with 6 decimals); without the rotation, or with the
rotation the other way (T Ω_toro Tᵀ), they do not agree (relative differences > 1e-2).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..errors import OptionError
from ..posegraph import rot2

__all__ = ["FORMATS", "FORMAT_LABEL", "Spec", "SPECS", "FORMAT_SPECS", "TAGS_OF", "FIX", "G2O_INFO_INDEX",
           "TORO_INFO_INDEX", "toro_to_g2o", "g2o_to_toro", "check_format"]

FORMATS = ("g2o", "toro")
FORMAT_LABEL = {"g2o": "g2o", "toro": "TORO"}


# ----------------------------------------------------------------------------- record types
class Spec(NamedTuple):
    tag: str
    fmt: str        # "g2o" or "toro"
    fields: tuple   # names of the tokens after the tag (for messages)
    n_ids: int      # how many of the leading fields are integer ids
    n_tokens: int   # tokens on a well-formed line, tag included


_VERTEX_FIELDS = ("id", "x", "y", "theta")
_G2O_EDGE_FIELDS = ("i", "j", "dx", "dy", "dtheta", "I11", "I12", "I13", "I22", "I23", "I33")
_TORO_EDGE_FIELDS = ("i", "j", "dx", "dy", "dtheta", "Ixx", "Ixy", "Iyy", "Itt", "Ixt", "Iyt")

SPECS = {spec.tag: spec for spec in [
    Spec("VERTEX_SE2", "g2o", _VERTEX_FIELDS, 1, 5),
    Spec("EDGE_SE2", "g2o", _G2O_EDGE_FIELDS, 2, 12),
    Spec("VERTEX2", "toro", _VERTEX_FIELDS, 1, 5),
    Spec("EDGE2", "toro", _TORO_EDGE_FIELDS, 2, 12),
]}
FORMAT_SPECS = {"g2o": (SPECS["VERTEX_SE2"], SPECS["EDGE_SE2"]),   # (vertex, edge) per format
                "toro": (SPECS["VERTEX2"], SPECS["EDGE2"])}
TAGS_OF = {"g2o": "VERTEX_SE2/EDGE_SE2", "toro": "VERTEX2/EDGE2"}
FIX = "FIX"

# Index maps from the six stored information entries to the symmetric 3×3 matrix (order x, y, θ).
G2O_INFO_INDEX = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])   # I11 I12 I13 I22 I23 I33
TORO_INFO_INDEX = np.array([[0, 1, 4], [1, 2, 5], [4, 5, 3]])  # Ixx Ixy Iyy Itt Ixt Iyt



# ----------------------------------------------------------------------------- information matrices
def toro_to_g2o(info_toro: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """Ω_g2o = Tᵀ Ω_toro T with T = blkdiag(R(dθ), 1), for (m, 3, 3) stacks; exactly symmetric."""
    T = rotation_block(dtheta)
    out = np.swapaxes(T, 1, 2) @ info_toro @ T
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def g2o_to_toro(info_g2o: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """Inverse of :func:`toro_to_g2o`: Ω_toro = T Ω_g2o Tᵀ."""
    T = rotation_block(dtheta)
    out = T @ info_g2o @ np.swapaxes(T, 1, 2)
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def rotation_block(dtheta: np.ndarray) -> np.ndarray:
    T = np.zeros((len(dtheta), 3, 3))
    T[:, :2, :2] = rot2(dtheta)
    T[:, 2, 2] = 1.0
    return T


def check_format(format) -> str | None:
    """``None`` or the lower-cased format name; ``OptionError`` for anything but g2o / TORO."""
    if format is None:
        return None
    f = str(format).lower()
    if f not in FORMATS:
        raise OptionError(f"format must be None, 'g2o' or 'toro', got {format!r}")
    return f
