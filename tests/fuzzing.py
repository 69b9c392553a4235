"""Seeded mutation fuzzer for the pose-graph reader and the CLI.

Shared by ``tests/test_fuzz.py`` (a bounded run in CI) and ``tests/fuzz_long.py`` (long runs for
developers, ``python tests/fuzz_long.py``). Not a test module itself (pytest only collects ``test_*.py``).

* **Seeds** — :func:`synthetic_seeds` (written by ``write_graph``, so fuzzing needs no dataset) and
  :func:`real_seeds` (small real files, or the first lines of larger ones).
* **Mutations** — :data:`MUTATIONS`, functions ``(data: bytes, rng: random.Random) -> bytes``;
  :func:`mutate` stacks 1–3 of them. Everything is drawn from the given ``random.Random``, so a run is
  reproducible from its seed.
* **Oracles** — :func:`check_read` (``read_graph`` either returns a ``PoseGraph`` that survives a
  write/read round trip bit for bit, or raises a ``ParseError`` honouring its documented contract;
  anything else is *unexpected*) and :func:`check_cli` (``main([...])`` returns 0 or 2 and never
  lets an exception escape).
"""

from __future__ import annotations

import contextlib
import io
import json
import random
import time
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lago_cvx.io import ParseError, read_graph, write_graph
from lago_cvx.posegraph import PoseGraph
from lago_cvx.synthetic import manhattan_world, random_graph

__all__ = [
    "MUTATIONS", "SPECIAL_TOKENS", "mutate", "synthetic_seeds", "real_seeds", "REAL_SEED_FILES",
    "Outcome", "check_read", "check_cli", "Tally", "count_lines",
]

# ----------------------------------------------------------------------------------------- seeds
#: Real files used as seeds: (relative path under the datasets folder, number of leading lines or None).
REAL_SEED_FILES = [
    ("gtsam/noisyToyGraph.txt", None),
    ("se-sync/MIT.g2o", 200),              # its first 200 lines are VERTEX lines only
    ("carlone/FR079_P_toro.graph", 200),   # idem (TORO)
]


def _head(data: bytes, n_lines: int) -> bytes:
    return b"".join(data.splitlines(keepends=True)[:n_lines])


def _connected_head(data: bytes, n_vertices: int) -> bytes:
    """The first ``n_vertices`` vertex lines plus every edge line among them (a small solvable
    graph: the first lines of MIT/FR079 contain no edge at all)."""
    keep = []
    for line in data.splitlines(keepends=True):
        toks = line.split()
        if len(toks) < 3:
            continue
        if toks[0].startswith(b"VERTEX") and int(toks[1]) < n_vertices:
            keep.append(line)
        elif toks[0].startswith(b"EDGE") and int(toks[1]) < n_vertices and int(toks[2]) < n_vertices:
            keep.append(line)
    return b"".join(keep)


def real_seeds(paths: dict) -> dict:
    """Seed files from real data. ``paths`` maps each relative path of :data:`REAL_SEED_FILES` to
    its location (missing entries are left out). Returns ``{name: bytes}``."""
    seeds = {}
    for rel, n_lines in REAL_SEED_FILES:
        if rel not in paths:
            continue
        data = Path(paths[rel]).read_bytes()
        name = rel.split("/")[-1]
        if n_lines is None:
            seeds[name] = data
        else:
            seeds[f"{name}[:{n_lines} lines]"] = _head(data, n_lines)
            seeds[f"{name}[first 60 poses + their edges]"] = _connected_head(data, 60)
    return seeds


def synthetic_seeds(workdir) -> dict:
    """Seed files written by ``write_graph`` (g2o and TORO, with and without vertex lines,
    non-contiguous ids, full information matrices). Returns ``{name: bytes}``."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    full = random_graph(8, 14, seed=3, information="full").graph
    grid = manhattan_world(30, seed=1).graph
    sparse_ids = PoseGraph(full.n_poses, full.tails, full.heads, full.delta_l, full.delta, full.information,
                           full.initial, ids=np.array([3, 5, 6, 10, 11, 12, 40, 1000]))
    cases = {
        "random_full.g2o": (full, "g2o"),
        "random_full.graph": (full, "toro"),
        "manhattan30.g2o": (grid, "g2o"),
        "edges_only.g2o": (grid.with_initial(None), "g2o"),
        "sparse_ids.g2o": (sparse_ids, "g2o"),
    }
    seeds = {}
    for name, (graph, fmt) in cases.items():
        seeds[name] = write_graph(workdir / name, graph, format=fmt).read_bytes()
    return seeds


# ------------------------------------------------------------------------------------- mutations
#: Replacement tokens: non-finite and overflowing numbers, non-numbers, non-ASCII digits, odd syntax.
SPECIAL_TOKENS = [
    b"NaN", b"nan", b"-nan", b"inf", b"-inf", b"+inf", b"Infinity", b"1e999", b"-1e999", b"1e-999",
    b"1e308", b"-1e308", b"1e-320", b"abc", b"", b"0x10", b"1_000", b"+-1", b"--1", b"1e", b"e5", b".",
    b"-", b"+", b"1.5", b"-0", b"0", b"-1", b"1.", b".5", b"1e+5", b"1E-5", b"99999999999999999999",
    b"9223372036854775808", b"-9223372036854775809", b"9007199254740993", b"1,5", b"1/2", b"None",
    "١٢٣".encode(), "１２".encode(), "²".encode(), "٣.٥".encode(), "Ⅻ".encode(), "𝟙".encode(),
    b"\xff", b"\xc3", b"0\x00", b"1\x0b2", b"1\x1c2", b"1\x0c",
]
_UNICODE = ["é", "Δθ", "\u00a0", "\u2003", "\u3000", "\u200b", "\u2028", "\u0085", "\ufeff", "😀", "١",
            "\u202e", "e\u0301", "ß", "İ", "\U0010ffff"]
_TAGS = [b"VERTEX_SE2", b"EDGE_SE2", b"VERTEX2", b"EDGE2", b"FIX", b"vertex_se2", b"EDGE_SE3:QUAT",
         b"VERTEX_XY", b"EDGE_SE2_XY", b"#EDGE_SE2", b"EDGE_SE2\x00", b"E\xc3\x89DGE"]


def _lines(data: bytes) -> list:
    return data.split(b"\n")


def _join(lines: list) -> bytes:
    return b"\n".join(lines)


def _data_lines(lines: list, prefix: bytes = b"") -> list:
    """Indices of lines whose first token starts with ``prefix`` (any non-blank line if empty)."""
    out = []
    for k, line in enumerate(lines):
        toks = line.split()
        if toks and toks[0].startswith(prefix) and not toks[0].startswith(b"#"):
            out.append(k)
    return out


def _pick_line(lines, rng, prefix=b""):
    idx = _data_lines(lines, prefix) or _data_lines(lines)
    return rng.choice(idx) if idx else None


def _edit_tokens(data, rng, edit, prefix=b""):
    lines = _lines(data)
    k = _pick_line(lines, rng, prefix)
    if k is None:
        return data
    toks = lines[k].split()
    edit(toks)
    lines[k] = b" ".join(toks)
    return _join(lines)


def m_truncate_line(data, rng):
    lines = _lines(data)
    k = _pick_line(lines, rng)
    if k is None:
        return data
    lines[k] = lines[k][: rng.randrange(len(lines[k]) + 1)]
    return _join(lines)


def m_truncate_file(data, rng):
    return data[: rng.randrange(len(data) + 1)]


def m_drop_token(data, rng):
    return _edit_tokens(data, rng, lambda t: t.pop(rng.randrange(len(t))))


def m_duplicate_token(data, rng):
    def edit(t):
        k = rng.randrange(len(t))
        t.insert(k, t[k])
    return _edit_tokens(data, rng, edit)


def m_swap_tokens(data, rng):
    def edit(t):
        a, b = rng.randrange(len(t)), rng.randrange(len(t))
        t[a], t[b] = t[b], t[a]
    return _edit_tokens(data, rng, edit)


def m_replace_token(data, rng):
    def edit(t):
        t[rng.randrange(len(t))] = rng.choice(SPECIAL_TOKENS)
    return _edit_tokens(data, rng, edit)


def m_replace_number(data, rng):
    """A number (not the tag) replaced by a special token — the most common real-world corruption."""
    def edit(t):
        if len(t) > 1:
            t[rng.randrange(1, len(t))] = rng.choice(SPECIAL_TOKENS)
    return _edit_tokens(data, rng, edit)


def m_replace_tag(data, rng):
    def edit(t):
        t[0] = rng.choice(_TAGS)
    return _edit_tokens(data, rng, edit)


def m_crlf(data, rng):
    return data.replace(b"\r\n", b"\n").replace(b"\n", b"\r\n")


def m_cr_only(data, rng):
    return data.replace(b"\n", b"\r")


def m_tabs(data, rng):
    if rng.random() < 0.5:
        return data.replace(b" ", b"\t")
    return bytes(c if c != 0x20 or rng.random() < 0.5 else 0x09 for c in data)


def m_extra_whitespace(data, rng):
    lines = _lines(data)
    k = rng.randrange(len(lines))
    pad = rng.choice([b"  ", b"\t", b" \t ", b"\x0b", b"\x0c", b"\r"])
    lines[k] = pad + lines[k].replace(b" ", b" " + pad) + pad
    return _join(lines)


def m_empty_lines(data, rng):
    lines = _lines(data)
    for _ in range(rng.randint(1, 5)):
        lines.insert(rng.randrange(len(lines) + 1), rng.choice([b"", b"   ", b"\t", b"\r", b" \r"]))
    return _join(lines)


def m_long_line(data, rng):
    """A line of about 100 000 characters: comment, one huge token, many tokens, or whitespace."""
    kind = rng.randrange(5)
    if kind == 0:
        line = b"#" + b"x" * 100_000
    elif kind == 1:
        line = b"EDGE_SE2 0 1 " + b"1" * 100_000 + b" 0 0 1 0 0 1 0 1"
    elif kind == 2:
        line = b"VERTEX_SE2 " + b" ".join([b"1.0"] * 25_000)
    elif kind == 3:
        line = b" " * 100_000
    else:
        line = b"VERTEX_SE2 0 0." + b"0" * 100_000 + b"1 0 0"
    lines = _lines(data)
    lines.insert(rng.randrange(len(lines) + 1), line)
    return _join(lines)


def m_random_bytes(data, rng):
    buf = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        pos = rng.randrange(len(buf) + 1)
        if rng.random() < 0.3:
            chunk = bytes(rng.choice(b"\x00\x01\x0b\x0c\x1c\x1f\x7f\x80\xa0\xc0\xff\xfe\r\n\t ") for _ in range(3))
        else:
            chunk = bytes(rng.randrange(256) for _ in range(rng.randint(1, 4)))
        buf[pos:pos] = chunk
    return bytes(buf)


def m_flip_bits(data, rng):
    if not data:
        return data
    buf = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        pos = rng.randrange(len(buf))
        buf[pos] ^= 1 << rng.randrange(8)
    return bytes(buf)


def m_bom(data, rng):
    bom = rng.choice([b"\xef\xbb\xbf", b"\xef\xbb\xbf\xef\xbb\xbf", b"\xff\xfe", b"\xfe\xff"])
    if rng.random() < 0.7:
        return bom + data
    lines = _lines(data)
    k = rng.randrange(len(lines))
    lines[k] = bom + lines[k]
    return _join(lines)


def m_utf16(data, rng):
    try:
        return data.decode("utf-8").encode(rng.choice(["utf-16", "utf-16-le", "utf-32"]))
    except UnicodeDecodeError:
        return data


def m_unicode_text(data, rng):
    text = rng.choice(_UNICODE).encode("utf-8", "surrogatepass")
    if rng.random() < 0.5:  # inside a data line, at a random byte position
        pos = rng.randrange(len(data) + 1)
        return data[:pos] + text + data[pos:]
    lines = _lines(data)
    lines.insert(rng.randrange(len(lines) + 1), rng.choice([b"# ", b""]) + text * rng.randint(1, 3))
    return _join(lines)


def m_swap_lines(data, rng):
    lines = _lines(data)
    if len(lines) < 2:
        return data
    a, b = rng.randrange(len(lines)), rng.randrange(len(lines))
    lines[a], lines[b] = lines[b], lines[a]
    return _join(lines)


def m_delete_line(data, rng):
    lines = _lines(data)
    k = _pick_line(lines, rng)
    if k is not None:
        del lines[k]
    return _join(lines)


def m_duplicate_line(data, rng):
    lines = _lines(data)
    k = _pick_line(lines, rng, b"EDGE")
    if k is not None:
        lines.insert(rng.randrange(len(lines) + 1), lines[k])
    return _join(lines)


def m_delete_vertex_lines(data, rng):
    lines = _lines(data)
    idx = _data_lines(lines, b"VERTEX")
    if not idx:
        return data
    if rng.random() < 0.3:
        drop = set(idx)  # all of them: an edge-only file (or an empty one)
    else:
        drop = set(rng.sample(idx, rng.randint(1, min(3, len(idx)))))
    return _join([ln for k, ln in enumerate(lines) if k not in drop])


def m_keep_only_vertices(data, rng):
    """Vertex lines only (possibly a single one): poses without any edge."""
    lines = _lines(data)
    idx = _data_lines(lines, b"VERTEX")
    if not idx:
        return data
    keep = idx[: rng.choice([1, 2, len(idx)])]
    return _join([lines[k] for k in keep]) + b"\n"


def m_duplicate_vertex_line(data, rng):
    lines = _lines(data)
    k = _pick_line(lines, rng, b"VERTEX")
    if k is None:
        return data
    dup = lines[k]
    if rng.random() < 0.5:  # same id, different pose
        toks = dup.split()
        if len(toks) > 2:
            toks[2] = b"12.5"
        dup = b" ".join(toks)
    lines.insert(rng.randrange(len(lines) + 1), dup)
    return _join(lines)


def _info_positions(tag: bytes):
    """Token positions (tag = 0) of the information diagonal and of one off-diagonal entry."""
    if tag == b"EDGE2":  # Ixx Ixy Iyy Itt Ixt Iyt
        return [6, 8, 9], [7, 10, 11]
    return [6, 9, 11], [7, 8, 10]  # g2o: I11 I12 I13 I22 I23 I33


def m_indefinite_information(data, rng):
    lines = _lines(data)
    k = _pick_line(lines, rng, b"EDGE")
    if k is None:
        return data
    toks = lines[k].split()
    if len(toks) != 12:
        return data
    diag, off = _info_positions(toks[0])
    how = rng.randrange(4)
    if how == 0:
        toks[rng.choice(diag)] = rng.choice([b"-1", b"0", b"-0.0", b"-1e-300"])
    elif how == 1:  # |off-diagonal| > sqrt(product of its diagonal entries)
        vals = []
        for d in diag:
            try:
                vals.append(abs(float(toks[d])))
            except ValueError:
                vals.append(1.0)
        toks[rng.choice(off)] = repr(2.0 * max(vals) + 1.0).encode()
    elif how == 2:  # all entries equal: rank one
        for p in diag + off:
            toks[p] = b"1"
    else:  # not symmetric-able trouble: absurd magnitudes
        toks[rng.choice(diag + off)] = rng.choice([b"1e200", b"-1e200", b"1e-200", b"1e154", b"1e103"])
    lines[k] = b" ".join(toks)
    return _join(lines)


def m_self_loop(data, rng):
    def edit(t):
        if len(t) > 2:
            t[2] = t[1]
    return _edit_tokens(data, rng, edit, b"EDGE")


def m_unknown_or_odd_id(data, rng):
    def edit(t):
        if len(t) > 1:
            t[rng.choice([1, 2]) if len(t) > 2 else 1] = rng.choice(
                [b"123456", b"-1", b"-0", b"+3", b"007", b"9223372036854775807", b"18446744073709551616",
                 b"1e3", b"2.0", b"0x1"])
    return _edit_tokens(data, rng, edit, rng.choice([b"EDGE", b"VERTEX"]))


def m_huge_measurement(data, rng):
    def edit(t):
        if len(t) > 5:
            t[rng.choice([3, 4, 5]) if t[0].startswith(b"EDGE") else rng.choice([2, 3, 4])] = rng.choice(
                [b"1e300", b"-1e300", b"1e154", b"1e-300", b"6.283185307179586e15", b"1e20"])
    return _edit_tokens(data, rng, edit)


def m_insert_special_line(data, rng):
    line = rng.choice([
        b"FIX 0", b"FIX", b"FIX a", b"FIX 0 1 2", b"# comment", b"#", b"   # indented comment \xff",
        b"VERTEX_SE2 77 0 0 0", b"VERTEX2 77 0 0 0", b"EDGE_SE2 0 77 1 0 0 1 0 0 1 0 1",
        b"EDGE2 0 1 1 0 0 1 0 1 1 0 0", b"EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1", b"EDGE_SE2 1 0 1 0 0 1 0 0 1 0 1",
        b"VERTEX_SE2", b"EDGE_SE2", b"\x00", b"\xef\xbb\xbfVERTEX_SE2 0 0 0 0",
    ])
    lines = _lines(data)
    lines.insert(rng.randrange(len(lines) + 1), line)
    return _join(lines)


def m_empty_file(data, rng):
    return rng.choice([b"", b"\n", b"# only a comment\n", b"\xef\xbb\xbf", b"   \n\t\n"])


#: name → mutation ``(bytes, random.Random) -> bytes``.
MUTATIONS = {f.__name__[2:]: f for f in [
    m_truncate_line, m_truncate_file, m_drop_token, m_duplicate_token, m_swap_tokens, m_replace_token,
    m_replace_number, m_replace_tag, m_crlf, m_cr_only, m_tabs, m_extra_whitespace, m_empty_lines,
    m_long_line, m_random_bytes, m_flip_bits, m_bom, m_utf16, m_unicode_text, m_swap_lines,
    m_delete_line, m_duplicate_line, m_delete_vertex_lines, m_keep_only_vertices,
    m_duplicate_vertex_line, m_indefinite_information, m_self_loop, m_unknown_or_odd_id,
    m_huge_measurement, m_insert_special_line, m_empty_file,
]}
#: Relative weights (the rest 1): structure-preserving token edits are the most interesting.
_WEIGHTS = {"replace_number": 4, "replace_token": 2, "indefinite_information": 2, "empty_file": 0.2,
            "utf16": 0.5, "keep_only_vertices": 0.5, "truncate_file": 0.5}


def mutate(data: bytes, rng: random.Random, *, max_stack: int = 3) -> tuple[bytes, list]:
    """Apply 1..``max_stack`` random mutations (weighted); returns ``(mutant, names applied)``."""
    names = list(MUTATIONS)
    weights = [_WEIGHTS.get(n, 1.0) for n in names]
    applied = []
    for _ in range(rng.randint(1, max_stack)):
        name = rng.choices(names, weights)[0]
        data = MUTATIONS[name](data, rng)
        applied.append(name)
    return data, applied


# --------------------------------------------------------------------------------------- oracles
def count_lines(data: bytes) -> int:
    """Number of lines as the reader numbers them (split on LF; a final LF opens an empty line). A file with a CR and
    no LF in its first 64 KiB has classic Mac OS line ends, each CR read as an LF (``io.careful.read_bytes``)."""
    head = data[:65536]
    if b"\r" in head and b"\n" not in head:
        data = data.replace(b"\r", b"\n")
    return data.count(b"\n") + 1


@dataclass
class Outcome:
    """``kind``: "parsed", "parse_error" or "unexpected" (read); "exit0", "exit2" or "unexpected"
    (CLI). ``detail``: the error message, or for "unexpected" what went wrong (with traceback)."""
    kind: str
    detail: str = ""
    warnings: list = field(default_factory=list)   # "Category: message" of warnings raised meanwhile
    seconds: float = 0.0                           # wall time of the call


def _blank(data: bytes, line: int) -> bool:
    lines = data.split(b"\n")
    if not 1 <= line <= len(lines):
        return False
    return not lines[line - 1].decode("utf-8", "surrogateescape").split()


def check_read(path, *, roundtrip_dir=None, time_limit: float | None = None) -> Outcome:
    """Run ``read_graph(path)`` and check its contract.

    * success: a ``PoseGraph``; if ``roundtrip_dir`` is given, writing it (g2o, angles as stored) and
      reading it back must give the same graph bit for bit (``io`` module docstring);
    * ``ParseError``: ``.line`` is None or in 1..number of lines and names a non-blank line; ``str``
      contains the file name, is one line and equals ``"{path}:{line}: {problem}"``;
    * any other exception, or a broken contract: "unexpected";
    * taking longer than ``time_limit`` seconds (if given) is "unexpected" too (a pathological input:
      the reader is meant to be linear-time)."""
    path = Path(path)
    data = path.read_bytes()
    t = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        outcome = _check_read(path, data, roundtrip_dir)
    outcome.seconds = time.perf_counter() - t
    outcome.warnings = _warning_list(caught)
    if time_limit is not None and outcome.seconds > time_limit and outcome.kind != "unexpected":
        return Outcome("unexpected", f"slow: read_graph took {outcome.seconds:.3g} s (limit {time_limit} s; "
                                     f"outcome {outcome.kind}: {outcome.detail[:200]})",
                       outcome.warnings, outcome.seconds)
    return outcome


def _warning_list(caught) -> list:
    return [f"{w.category.__name__}: {w.message} ({Path(w.filename).name}:{w.lineno})" for w in caught]


def _check_read(path: Path, data: bytes, roundtrip_dir) -> Outcome:
    try:
        graph = read_graph(path)
    except ParseError as err:
        msg = str(err)
        n = count_lines(data)
        problems = []
        if err.line is not None and not 1 <= err.line <= n:
            problems.append(f"line {err.line!r} outside 1..{n}")
        elif err.line is not None and _blank(data, err.line):
            problems.append(f"line {err.line} is blank")
        if path.name not in msg:
            problems.append("message does not contain the file name")
        if "\n" in msg:
            problems.append("message is not one line")
        expected = f"{err.path}: {err.problem}" if err.line is None else f"{err.path}:{err.line}: {err.problem}"
        if msg != expected:
            problems.append(f"str(err) is not 'path:line: problem' ({expected!r})")
        if problems:
            return Outcome("unexpected", f"ParseError contract broken ({'; '.join(problems)}): {msg[:300]!r}")
        return Outcome("parse_error", msg)
    except Exception:  # noqa: BLE001 - that is the point
        return Outcome("unexpected", traceback.format_exc(limit=6))
    if not isinstance(graph, PoseGraph):
        return Outcome("unexpected", f"read_graph returned {type(graph).__name__}")
    if roundtrip_dir is not None:
        try:
            # in the input's own format (cost): a TORO graph written as g2o is the same cost to rounding only
            fmt = "toro" if graph.cost == "paper" else "g2o"
            out = write_graph(Path(roundtrip_dir) / ("rt_" + path.name + "." + fmt), graph, wrap_angles=False,
                              format=fmt)
            again = read_graph(out)
            if not again.equals(graph):
                return Outcome("unexpected", "write_graph → read_graph does not reproduce the graph")
        except Exception:  # noqa: BLE001
            return Outcome("unexpected", "round trip failed:\n" + traceback.format_exc(limit=6))
    return Outcome("parsed", repr(graph))


def check_cli(path, command: str, *, time_limit: float | None = None) -> Outcome:
    """Run ``lago_cvx.cli.main([command, path, "--json"])``: exit status 0 (stdout one JSON object)
    or 2 (last stderr line ``lago-cvx: error: …``); status 1, another status, an escaping exception
    or (if given) more than ``time_limit`` seconds is "unexpected"."""
    from lago_cvx.cli import main

    out, err = io.StringIO(), io.StringIO()
    t = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        outcome = _check_cli(main, path, command, out, err)
    outcome.seconds = time.perf_counter() - t
    outcome.warnings = _warning_list(caught) + outcome.warnings
    if time_limit is not None and outcome.seconds > time_limit and outcome.kind != "unexpected":
        return Outcome("unexpected", f"slow: {command} took {outcome.seconds:.3g} s (limit {time_limit} s; "
                                     f"outcome {outcome.kind})", outcome.warnings, outcome.seconds)
    return outcome


def _check_cli(main, path, command, out, err) -> Outcome:
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = main([command, str(path), "--json"])
    except BaseException as exc:  # noqa: BLE001 - SystemExit included: main must return, not exit
        return Outcome("unexpected", f"{command}: exception escaped main(): {exc!r}\n"
                                     + traceback.format_exc(limit=6))
    stderr = err.getvalue().strip()
    if rc == 0:
        constants = []
        try:
            json.loads(out.getvalue(), parse_constant=lambda c: constants.append(c) or float(c))
        except ValueError as exc:
            return Outcome("unexpected", f"{command}: exit 0 but stdout is not JSON ({exc})")
        # not a failure, but worth seeing: a "successful" run whose numbers are NaN/Infinity
        return Outcome("exit0", warnings=[f"note: {command} exit 0 with {c} in its JSON output"
                                          for c in sorted(set(constants))])
    if rc == 2:
        last = stderr.splitlines()[-1] if stderr else ""
        if not last.startswith("lago-cvx: error: "):
            return Outcome("unexpected", f"{command}: exit 2 without a 'lago-cvx: error:' line: {stderr[:300]!r}")
        return Outcome("exit2", last)
    return Outcome("unexpected", f"{command}: exit status {rc}: {stderr[:500]}")


@dataclass
class Tally:
    """Counts per outcome kind, overall and per mutation name; keeps the unexpected cases."""
    counts: dict = field(default_factory=dict)
    by_mutation: dict = field(default_factory=dict)
    unexpected: list = field(default_factory=list)   # (label, mutations, detail, mutant bytes)
    warned: int = 0                                  # runs that raised at least one warning
    warnings: dict = field(default_factory=dict)     # warning text → (count, first label, mutant bytes)

    def add(self, outcome: Outcome, mutations, label: str = "", data: bytes = b""):
        self.counts[outcome.kind] = self.counts.get(outcome.kind, 0) + 1
        for name in set(mutations):
            row = self.by_mutation.setdefault(name, {})
            row[outcome.kind] = row.get(outcome.kind, 0) + 1
        if outcome.kind == "unexpected":
            self.unexpected.append((label, list(mutations), outcome.detail, data))
        if outcome.warnings:
            self.warned += 1
        for w in set(outcome.warnings):
            count, first, first_data = self.warnings.get(w, (0, label, data))
            self.warnings[w] = (count + 1, first, first_data)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def get(self, kind: str) -> int:
        return self.counts.get(kind, 0)
