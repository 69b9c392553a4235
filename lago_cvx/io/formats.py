"""The g2o and TORO text formats of planar pose graphs: their record types and the TORO ↔ g2o
conversion of the information matrices. Reading is ``reader.py``, writing ``writer.py``.

Formats
=======
Both formats are line based: one record per line, whitespace-separated tokens (spaces or tabs; LF, CRLF
or, in a file without LF, CR line ends; a UTF-8 byte-order mark is skipped). A token that starts with ``#`` starts a comment that
runs to the end of the line: blank lines and whole-line comments are skipped, and
``EDGE_SE2 0 1 … 0 0 1   # odometry`` is the edge (a ``#`` inside a token, as in ``1#2``, is not a
comment but a bad number). Pose ids are integers; they need not be contiguous or start at 0
(``PoseGraph.ids`` keeps them, sorted, and edge endpoints become indices into it).

**g2o** (``VERTEX_SE2`` / ``EDGE_SE2``)::

    VERTEX_SE2 id x y θ
    EDGE_SE2   i j dx dy dθ I11 I12 I13 I22 I23 I33

The edge carries pose j measured in the frame of pose i and the *upper triangle* (row-major, order
x, y, θ) of the 3×3 information matrix Ω of the error ``e = [R_iᵀ(p_j − p_i) − Δˡ ; θ_j − θ_i − δ]``
— the convention of :mod:`lago_cvx.posegraph`. ``FIX id [id ...]`` lines are legal g2o; they are
validated (integer ids) and ignored, with one warning per file: the estimate is anchored at the smallest
id (``lago(graph, anchor=ID)``, CLI ``--anchor ID``, choose another).

**TORO / HOG-Man** (``VERTEX2`` / ``EDGE2``)::

    VERTEX2 id x y θ
    EDGE2   i j dx dy dθ Ixx Ixy Iyy Iθθ Ixθ Iyθ

Same measurement, but the six information entries come in a different order (HOG-Man's
``inf_ff inf_fs inf_ss inf_rr inf_fr inf_sr``; in error messages the fields are called
``Ixx Ixy Iyy Itt Ixt Iyt``, t standing for θ) **and in a different frame**. ``EQUIV i j`` lines (TORO:
a request to collapse the edge i–j, which TORO itself applies only when asked to) are validated (two
integer ids) and ignored, with one warning per file: every vertex and edge is kept as written.

Some files in the wild store g2o records under the TORO tag: ``EDGE2 i j dx dy dθ I11 I12 I13 I22 I23
I33`` (the g2o order and frame; e.g. ``w100_30.g2o`` and ``w20000.txt`` shipped with GTSAM). The order
is never guessed: ``read_graph(path, edge2_order="g2o")`` reads every ``EDGE2`` line exactly like an
``EDGE_SE2`` line, and when the TORO reading gives an information matrix that is not positive definite
while every ``EDGE2`` line of the file would be positive definite in the g2o order, the error says so
and names that option (and the other way round).

Records of other kinds are recognized only to say what they are: landmark records (``LANDMARK2``,
``BR``, ``VERTEX_XY``, ``EDGE_SE2_XY``, ``POINT2``, …) and 3-D records (``VERTEX_SE3:QUAT``,
``EDGE_SE3:QUAT``, ``VERTEX3``, ``EDGE3``, …) are a ``ParseError`` at their line with a message naming
the kind (:data:`NON_POSE_TAGS`). A file whose first record is ``VERTEX_SE3:QUAT`` or ``EDGE_SE3:QUAT`` is a
3-D graph: ``read_graph`` hands it to ``space.py``; such a record later in a planar file is a mix, refused.

The cost each format means
--------------------------
A file's information matrices are written for its format's error (``lago_cvx.conventions``): g2o's
``EDGE_SE2`` for e_g2o = t2v(Z⁻¹X_i⁻¹X_j), whose translation is in the **measurement's** frame, TORO's
``EDGE2`` for the seed's eq. (3), whose translation is in the frame of the **tail** i. The reader takes each
file's Ω_f for the cost asked (default: the format's, ``COST_OF_FORMAT``) and gives the graph the information
of eq. (3) (``PoseGraph.information``): Ω_f itself for ``"paper"``, T Ω_f Tᵀ with T = blkdiag(R(dθ), 1)
(``posegraph.to_tail_frame``) for ``"g2o"`` and ``"gtsam"`` — exactly the same cost at every pose. Writing
applies the inverse for g2o files (``posegraph.to_measurement_frame``) and writes the given matrices bit for
bit when the graph holds them.

Evidence (datasets README §2.3, re-checked by ``tests/test_costs.py``): SE-Sync's ``manhattan.g2o`` and
``CSAIL.g2o`` were produced from Carlone's ``M3500_P_toro.graph`` and ``CSAIL_P_toro.graph``. The twins
have the same endpoints and measurements, and every edge satisfies Ω_g2o = R(dθ)ᵀ Ω_toro R(dθ) on the
translational block to 1e-4 relative (the g2o files were printed with 6 decimals): each twin, read with its
own format's cost, is the same graph, and g2o's χ² of the g2o twin equals eq. (3)'s of the TORO twin at
every pose (CSAIL at one estimate: 38 486.456 both).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..errors import OptionError

__all__ = ["FORMATS", "FORMAT_LABEL", "Spec", "SPECS", "FORMAT_SPECS", "TAGS_OF", "TAGS_3D", "FIX", "EQUIV", "G2O_INFO_INDEX",
           "TORO_INFO_INDEX", "EDGE2_ORDERS", "NON_POSE_TAGS", "non_pose_problem",
           "check_format", "check_edge2_order"]

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
TAGS_3D = "VERTEX_SE3:QUAT/EDGE_SE3:QUAT"  # the records of a 3-D file (io/space.py)
FIX = "FIX"
EQUIV = "EQUIV"
#: How the six information entries of an ``EDGE2`` line are read: "toro" (the documented TORO order and
#: frame, the default) or "g2o" (exactly like ``EDGE_SE2``).
EDGE2_ORDERS = ("toro", "g2o")

_WHAT_IS_READ = "lago_cvx reads pose graphs (VERTEX_SE2/EDGE_SE2 or VERTEX2/EDGE2, planar; VERTEX_SE3:QUAT/EDGE_SE3:QUAT, 3-D)"
#: Tags of records that are not planar pose-graph records, by kind ("landmark" measurement,
#: "landmark position", "3-D").
NON_POSE_TAGS = {
    **dict.fromkeys(["LANDMARK", "LANDMARK2", "BR", "EDGE_SE2_XY", "EDGE_SE2_POINTXY", "EDGE_BEARING_SE2_XY",
                     "EDGE_SE2_POINTXY_BEARING", "EDGE_SE2_XY_CALIB", "EDGE_POINTXY", "EDGE_XY_PRIOR"],
                    "landmark"),
    **dict.fromkeys(["VERTEX_XY", "POINT2", "VERTEX_POINTXY"], "landmark position"),
    **dict.fromkeys(["VERTEX_SE3:QUAT", "EDGE_SE3:QUAT", "VERTEX_SE3:EXPMAP", "EDGE_SE3:EXPMAP", "VERTEX3",
                     "EDGE3", "VERTEX_SE3", "EDGE_SE3", "EDGE_SE3_PRIOR", "VERTEX_TRACKXYZ", "EDGE_SE3_TRACKXYZ",
                     "VERTEX_XYZ", "PARAMS_SE3OFFSET"], "3-D"),
}


_SE3_QUAT = ("VERTEX_SE3:QUAT", "EDGE_SE3:QUAT")  # read by io/space.py when a file starts with them


def non_pose_problem(tag: str) -> str | None:
    """The message for a recognized non-pose-graph tag, or None."""
    kind = NON_POSE_TAGS.get(tag)
    if kind == "landmark":
        return f"{tag!r} is a landmark measurement, not a pose–pose constraint: {_WHAT_IS_READ}"
    if kind == "landmark position":
        return f"{tag!r} is a landmark position, not a pose: {_WHAT_IS_READ}"
    if kind == "3-D" and tag in _SE3_QUAT:
        return (f"{tag!r} is a 3-D record in a file of planar records: a file cannot mix planar and 3-D records "
                "(3-D files start with VERTEX_SE3:QUAT/EDGE_SE3:QUAT records)")
    if kind == "3-D":
        return (f"{tag!r} is a 3-D record of a kind lago_cvx does not read (it reads 3-D graphs as "
                "VERTEX_SE3:QUAT/EDGE_SE3:QUAT, planar ones as VERTEX_SE2/EDGE_SE2 or VERTEX2/EDGE2)")
    return None

# Index maps from the six stored information entries to the symmetric 3×3 matrix (order x, y, θ).
G2O_INFO_INDEX = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])   # I11 I12 I13 I22 I23 I33
TORO_INFO_INDEX = np.array([[0, 1, 4], [1, 2, 5], [4, 5, 3]])  # Ixx Ixy Iyy Itt Ixt Iyt



# ----------------------------------------------------------------------------- information matrices
def check_edge2_order(edge2_order) -> str:
    """The ``EDGE2`` information order to use: "toro" for None, else "toro" or "g2o" (``OptionError``
    for anything else)."""
    if edge2_order is None:
        return "toro"
    order = str(edge2_order).lower()
    if order not in EDGE2_ORDERS:
        raise OptionError(f"edge2_order must be None, 'toro' or 'g2o', got {edge2_order!r}")
    return order


def check_format(format) -> str | None:
    """``None`` or the lower-cased format name; ``OptionError`` for anything but g2o / TORO."""
    if format is None:
        return None
    f = str(format).lower()
    if f not in FORMATS:
        raise OptionError(f"format must be None, 'g2o' or 'toro', got {format!r}")
    return f
