"""Reading and writing planar pose graphs in the g2o (``VERTEX_SE2`` / ``EDGE_SE2``) and TORO
(``VERTEX2`` / ``EDGE2``) text formats.

* ``formats.py`` — the record types, the information-matrix orders and the TORO ↔ g2o conversion of the
  information (with the evidence for its direction);
* ``reader.py`` — ``read_graph`` and ``detect_format``; every problem with a file raises ``ParseError``
  naming ``file:line`` and the offending token;
* ``writer.py`` — ``write_graph`` (records formatted in blocks, bytes as ``repr`` writes them);
* ``output.py`` — ``open_output`` (atomic replace, symlinks written through, FIFOs and devices
  streamed, ``"-"`` for standard output, one-line ``OutputError``) and ``same_file``.
"""

from ..errors import OutputError, ParseError
from .output import open_output, same_file
from .reader import detect_format, read_graph
from .writer import write_graph

__all__ = ["ParseError", "OutputError", "read_graph", "write_graph", "detect_format", "open_output", "same_file"]
