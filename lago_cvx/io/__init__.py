"""Reading and writing planar pose graphs in the g2o (``VERTEX_SE2`` / ``EDGE_SE2``) and TORO
(``VERTEX2`` / ``EDGE2``) text formats, and 3-D ones in g2o's (``VERTEX_SE3:QUAT`` / ``EDGE_SE3:QUAT``, ``space.py``).

* ``formats.py`` — the record types (and the landmark / 3-D ones recognized only to name them), the
  information-matrix orders (``edge2_order``) and the TORO ↔ g2o conversion of the information (with
  the evidence for its direction);
* ``reader.py`` — ``read_graph`` and ``detect_format``: the fast path, else the careful parser, then
  the semantic checks, the warnings (FIX, EQUIV) and the ``PoseGraph``; every problem with a file raises
  ``ParseError`` naming ``file:line`` and the offending token;
* ``fastpath.py`` — ordinary files in chunked NumPy passes and one bulk number conversion; anything
  unusual is left to ``careful.py``, the line-by-line parser that names every problem;
* ``writer.py`` — ``write_graph``: records formatted column by column (``floatfmt.py``: ``repr`` of
  whole arrays, byte for byte), bytes as ``%d`` / ``%r`` would write them;
* ``output.py`` — ``open_output`` (atomic replace keeping permissions, symlinks written through, FIFOs
  and character devices streamed, ``"-"`` for standard output, one-line ``OutputError``) and
  ``same_file`` (the same file through symbolic and hard links).
"""

from ..errors import OutputError, ParseError
from .output import open_output, same_file
from .reader import detect_format, read_graph
from .writer import write_bytes, write_graph

__all__ = ["ParseError", "OutputError", "read_graph", "write_graph", "write_bytes", "detect_format",
           "open_output", "same_file"]
