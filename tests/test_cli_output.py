"""A command line a user can trust: where ``-o`` writes (regular files atomically, through links, streamed to
FIFOs, devices and standard output), what ends in exit 2 (every mistake of the user's, one line, no temp
names) and never in "internal error", non-finite estimates, resource limits (exit 4), messages in CLI
terms, and the ``datasets`` and ``plot`` commands."""

from __future__ import annotations

import json
import os
import stat
import threading
from pathlib import Path

import pytest

from lago_cvx.cli import main
from lago_cvx.io import read_graph

TRIANGLE = ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\n"
            "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 1 2 1 0 0.1 1 0 0 1 0 1\nEDGE_SE2 0 2 2.1 0 0 1 0 0 1 0 1\n")


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "internal error" not in lines[0] and "Traceback" not in err
    return lines[0]


@pytest.fixture
def graph_file(tmp_path):
    f = tmp_path / "g.g2o"
    f.write_text(TRIANGLE)
    return f


# ------------------------------------------------------------------------------------ -o targets
def test_regular_file_is_replaced_atomically_keeping_its_mode(capsys, tmp_path, graph_file):
    out = tmp_path / "out.g2o"
    out.write_text("old")
    out.chmod(0o640)
    code, _, err = run(capsys, "solve", graph_file, "-o", out)
    assert code == 0, err
    assert read_graph(out).n_poses == 3 and stat.S_IMODE(out.stat().st_mode) == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.g2o", "out.g2o"]  # no temp file left


def test_symlink_stays_a_link_and_its_target_is_written(capsys, tmp_path, graph_file):
    target = tmp_path / "target.g2o"
    target.write_text("old")
    link = tmp_path / "link.g2o"
    link.symlink_to(target)
    code, _, err = run(capsys, "solve", graph_file, "-o", link)
    assert code == 0, err
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert read_graph(target).n_poses == 3


def test_fifo_reader_gets_the_estimate_and_it_stays_a_fifo(capsys, tmp_path, graph_file):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = {}

    def reader():
        with open(fifo, "rb") as f:
            got["data"] = f.read()

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    code, _, err = run(capsys, "solve", graph_file, "-o", fifo)
    t.join(timeout=30)
    if t.is_alive():  # nothing was written into the FIFO: unblock the reader before failing
        fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK) if stat.S_ISFIFO(fifo.stat().st_mode) else None
        if fd is not None:
            os.close(fd)
        pytest.fail("the FIFO's reader got nothing")
    assert code == 0, err
    assert stat.S_ISFIFO(fifo.stat().st_mode)
    assert got["data"].startswith(b"VERTEX_SE2 0 ") and got["data"].count(b"EDGE_SE2") == 3


def _device(tmp_path, name: str, minor: int) -> Path:
    """A private copy of a Linux memory device (1, minor): /dev/null is (1, 3), /dev/full (1, 7). The tests
    never aim at the system's own nodes: a regression there would replace them for the whole machine."""
    dev = tmp_path / name
    try:
        os.mknod(dev, stat.S_IFCHR | 0o666, os.makedev(1, minor))
        with open(dev, "wb") as f:
            f.write(b"")
    except (OSError, AttributeError) as exc:
        pytest.skip(f"cannot make a character device here ({exc})")
    return dev


def test_a_device_is_written_to_not_replaced(capsys, tmp_path, graph_file):
    null = _device(tmp_path, "null", 3)
    code, _, err = run(capsys, "solve", graph_file, "-o", null)
    assert code == 0, err
    assert stat.S_ISCHR(null.stat().st_mode)


def test_a_full_device_is_a_clear_error_and_stays_a_device(capsys, tmp_path, graph_file):
    full = _device(tmp_path, "full", 7)
    code, _, err = run(capsys, "solve", graph_file, "-o", full)
    assert code == 2
    line = one_line(err)
    assert str(full) in line and "No space left" in line
    assert stat.S_ISCHR(full.stat().st_mode)


@pytest.mark.parametrize("argv", [["info", "{f}", "--json"], ["solve", "{f}"], ["solve", "{f}", "--json"],
                                  ["solve", "{f}", "-o", "-"], ["certify", "{f}"]],
                         ids=["info-json", "solve", "solve-json", "solve-dash", "certify"])
def test_standard_output_on_a_full_device_exits_2_in_one_line(tmp_path, graph_file, argv):
    """Standard output that cannot be written (a full disk) is bad output, exit 2 and one line — not an internal
    error — whether the report, the JSON or the estimate goes there; a whole process, as a shell runs it."""
    import subprocess
    import sys

    full = _device(tmp_path, "full", 7)
    with open(full, "wb") as out:
        done = subprocess.run([sys.executable, "-m", "lago_cvx", *(a.format(f=graph_file) for a in argv)],
                              stdout=out, stderr=subprocess.PIPE, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert one_line(done.stderr) == "lago-cvx: error: cannot write standard output: No space left on device"


def test_dash_writes_to_stdout_and_the_summary_to_stderr(capsys, graph_file):
    code, out, err = run(capsys, "solve", graph_file, "-o", "-")
    assert code == 0
    assert out.startswith("VERTEX_SE2 0 ") and out.count("EDGE_SE2") == 3
    assert "LAGO (" in err and "estimate written to standard output" in err
    assert not Path("-").exists()
    code, _, err = run(capsys, "solve", graph_file, "-o", "-", "--json")
    assert code == 2 and "choose one" in one_line(err)


@pytest.mark.parametrize("make, fragment", [
    (lambda d: "", "output file name is empty"),
    (lambda d: d / "missing_dir" / "out.g2o", "does not exist"),
    (lambda d: d, "is a directory"),
    (lambda d: "/proc/version", "/proc/version"),
])
def test_unwritable_targets_exit_2_one_line_without_temp_names(capsys, tmp_path, graph_file, make, fragment):
    target = make(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    code, out, err = run(capsys, "solve", graph_file, "-o", target)
    assert code == 2 and out == ""
    line = one_line(err)
    assert fragment in line and ".tmp" not in line and ".lago-cvx" not in line
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_unwritable_directory_exit_2(capsys, tmp_path, graph_file):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):
            pytest.skip("running with privileges that ignore directory permissions (root)")
        code, _, err = run(capsys, "solve", graph_file, "-o", locked / "out.g2o")
        assert code == 2 and "locked" in one_line(err)
    finally:
        locked.chmod(0o700)


def test_input_file_is_not_overwritten_through_a_link(capsys, tmp_path, graph_file):
    link = tmp_path / "alias.g2o"
    link.symlink_to(graph_file)
    before = graph_file.read_bytes()
    code, _, err = run(capsys, "solve", graph_file, "-o", link)
    assert code == 2 and "refusing to overwrite the input file" in one_line(err)
    assert graph_file.read_bytes() == before


def test_demo_out_dir_that_is_a_file_exit_2(capsys, tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    code, _, err = run(capsys, "demo", "--poses", "50", "--out-dir", f)
    assert code == 2 and "is not a directory" in one_line(err)


# -------------------------------------------------------------------------- options and overflow
@pytest.mark.parametrize("argv", [
    ["solve", "{f}", "--refine", "--max-iterations", "-5"],
    ["certify", "{f}", "--max-iterations", "-1"],
    ["solve", "{f}", "--max-nodes", "0"],
    ["solve", "{f}", "--max-shift", "-1"],
    ["solve", "{f}", "--time-limit", "-2"],
    ["generate", "--poses", "-3", "-o", "x.g2o"],
    ["generate", "--sigma-xy", "-0.1", "-o", "x.g2o"],
    ["plot", "{f}", "--every", "0", "-o", "x.png"],
])
def test_negative_options_exit_2(capsys, graph_file, argv):
    with pytest.raises(SystemExit) as exc:
        main([a.format(f=graph_file) for a in argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "error: argument" in err and "internal" not in err


@pytest.mark.parametrize("command", ["solve", "certify"])
def test_overflowing_graph_exit_2_and_writes_nothing(capsys, tmp_path, command):
    f = tmp_path / "huge.g2o"
    f.write_text(TRIANGLE.replace("EDGE_SE2 0 1 1 0 0", "EDGE_SE2 0 1 1e200 0 0")
                 .replace("EDGE_SE2 0 2 2.1 0 0", "EDGE_SE2 0 2 -1e200 0 0"))
    out = tmp_path / "out.g2o"
    code, stdout, err = run(capsys, command, f, "-o", out)
    assert code == 2 and stdout == ""
    line = one_line(err)
    assert "not finite" in line and "RuntimeWarning" not in err
    assert not out.exists()


# ------------------------------------------------------------------------------- messages in CLI terms
def test_broken_chain_message_speaks_cli_and_names_missing_ids(capsys, tmp_path):
    f = tmp_path / "ids.g2o"
    f.write_text("VERTEX_SE2 10 0 0 0\nVERTEX_SE2 12 1 0 0\nVERTEX_SE2 17 2 0 0\n"
                 "EDGE_SE2 10 12 1 0 0 1 0 0 1 0 1\nEDGE_SE2 12 17 1 0 0 1 0 0 1 0 1\n")
    code, _, err = run(capsys, "solve", f, "--route", "seed")
    line = one_line(err)
    assert code == 2 and "jump from 10 to 12" in line and "no pose has id 11" in line
    assert "--spanning-tree bfs" in line and "spanning_tree=" not in line
    assert "between poses 10 and 11" not in line
    code, out, _ = run(capsys, "solve", f, "--route", "seed", "--spanning-tree", "bfs", "--json")
    assert code == 0 and json.loads(out)["n_poses"] == 3


# ------------------------------------------------------------------------------------ datasets, plot
def test_datasets_list_verify_path_without_network(capsys, monkeypatch, tmp_path):
    from lago_cvx.datasets import DATASET_FILES, MANIFEST

    monkeypatch.setenv("LAGO_CVX_CACHE", str(tmp_path / "cache"))
    src = tmp_path / "data"
    (src / "gtsam").mkdir(parents=True)
    toy = "gtsam/noisyToyGraph.txt"
    (src / toy).write_bytes(_toy_bytes())
    monkeypatch.setenv("LAGO_CVX_DATASETS", str(src))
    code, out, _ = run(capsys, "datasets", "list", "--json")
    rows = {r["file"]: r for r in json.loads(out)["datasets"]}
    assert code == 0 and set(rows) == set(DATASET_FILES)
    assert rows[toy]["path"] == str(src / toy) and rows[toy]["sha256"] == MANIFEST[toy].sha256
    assert rows[toy]["source"].startswith("https://raw.githubusercontent.com/borglab/gtsam/")
    code, out, _ = run(capsys, "datasets", "verify", toy, "--json")
    assert code == 0 and json.loads(out)["datasets"] == [{"file": toy, "path": str(src / toy), "status": "ok"}]
    (src / toy).write_bytes(_toy_bytes() + b"\n# tampered\n")
    code, out, _ = run(capsys, "datasets", "verify", toy, "--json")
    assert code == 2 and json.loads(out)["datasets"][0]["status"] == "mismatch"
    code, out, _ = run(capsys, "datasets", "path", toy)
    assert code == 0 and out.strip() == str(src / toy)
    code, _, err = run(capsys, "datasets", "verify", "nope.g2o")
    assert code == 2 and "unknown dataset" in one_line(err)


def _toy_bytes() -> bytes:
    from conftest import dataset_path

    return Path(dataset_path("gtsam/noisyToyGraph.txt")).read_bytes()


def test_datasets_fetch_from_a_local_mirror(capsys, monkeypatch, tmp_path):
    """``fetch`` downloads into the cache and checks SHA-256; here from a local HTTP mirror (no network)."""
    pytest.importorskip("pooch", reason="fetching needs the datasets extra (pooch)")
    import functools
    import http.server

    from lago_cvx.datasets import MANIFEST

    toy = "gtsam/noisyToyGraph.txt"
    src = MANIFEST[toy]
    root = tmp_path / "mirror"
    where = root / src.repository / src.commit / src.path
    where.parent.mkdir(parents=True)
    where.write_bytes(_toy_bytes())
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(root))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        monkeypatch.setenv("LAGO_CVX_DATASETS_MIRROR", f"http://127.0.0.1:{server.server_address[1]}")
        monkeypatch.setenv("LAGO_CVX_DATASETS", str(tmp_path / "empty"))
        monkeypatch.setenv("LAGO_CVX_CACHE", str(tmp_path / "cache"))
        monkeypatch.chdir(tmp_path)  # no ../shared/datasets beside the working directory
        import lago_cvx.datasets as D

        monkeypatch.setattr(D, "_project_candidates", lambda: [])
        code, out, err = run(capsys, "datasets", "fetch", toy, "--json")
        assert code == 0, err
        got = Path(json.loads(out)["datasets"][0]["path"])
        assert got == tmp_path / "cache" / toy and got.read_bytes() == _toy_bytes()
        code, out, _ = run(capsys, "datasets", "verify", toy, "--json")
        assert code == 0 and json.loads(out)["datasets"][0]["status"] == "ok"
    finally:
        server.shutdown()


def test_plot_draws_graph_estimate_and_ellipses(capsys, tmp_path):
    world = tmp_path / "w.g2o"
    assert run(capsys, "generate", "--poses", "120", "--seed", "1", "-o", world)[0] == 0
    fig = tmp_path / "fig.png"
    code, out, err = run(capsys, "plot", world, "-o", fig, "--covariances", "--every", "20", "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["n_ellipses"] == 6 and fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    est = tmp_path / "est.g2o"
    assert run(capsys, "solve", world, "-o", est)[0] == 0
    svg = tmp_path / "fig.svg"
    code, _, err = run(capsys, "plot", world, est, "-o", svg)
    assert code == 0, err and svg.read_text().lstrip().startswith("<?xml")
    code, _, err = run(capsys, "plot", world, "-o", tmp_path / "fig.jpeg")
    assert code == 2 and ".png, .svg or .pdf" in one_line(err)
    other = tmp_path / "other.g2o"
    other.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n")
    code, _, err = run(capsys, "plot", world, other, "-o", fig)
    assert code == 2 and "no vertex for pose id" in one_line(err)


def test_ambiguous_tree_rounding_warning_suggests_the_chordal_regularizer(capsys, tmp_path):
    world = tmp_path / "noisy.g2o"
    assert run(capsys, "generate", "--poses", "1500", "--seed", "2", "--sigma-theta", "0.25", "-o", world)[0] == 0
    code, _, err = run(capsys, "solve", world, "--regularization", "tree")
    warnings = [ln for ln in err.splitlines() if "WARNING" in ln]
    assert code == 0 and len(warnings) == 1, err  # said once
    assert "ambiguous" in warnings[0] and "--regularization chordal" in warnings[0]
    assert 'regularization="chordal"' not in warnings[0]


def test_progress_is_drawn_on_a_terminal_and_silent_otherwise(monkeypatch):
    import io
    from types import SimpleNamespace

    from lago_cvx.cli.common import ProgressBar, progress_callback

    buf = io.StringIO()
    bar = ProgressBar(buf)
    bar("phase 3: factorization", 0.0)
    bar("phase 3: factorization", 0.5)
    bar("phase 3: factorization", 1.0)
    text = buf.getvalue()
    assert text.count("\r") == 3 and text.endswith("100 %\n") and " 50 %" in text
    assert progress_callback(SimpleNamespace(json=True)) is None  # --json: machine output, no bar
    monkeypatch.setattr("sys.stderr", io.StringIO())  # not a terminal
    assert progress_callback(SimpleNamespace(json=False)) is None


@pytest.mark.parametrize("text, argv, fragment", [
    ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\nVERTEX_SE2 3 3 0 0\n"
     "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 2 3 1 0 0 1 0 0 1 0 1\n", ["solve"], "is not connected"),
    ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n", ["solve"], "no edges"),
    ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 3 3 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"
     "EDGE_SE2 1 3 1 0 0 1 0 0 1 0 1\n", ["solve", "--route", "seed"], "odometric chain is broken"),
    ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n", ["solve", "--anchor", "9"],
     "no pose with id 9"),
], ids=["disconnected", "no-edges", "broken-chain", "unknown-anchor"])
def test_an_unusable_graph_is_named_by_its_file(capsys, tmp_path, text, argv, fragment):
    f = tmp_path / "odd.g2o"
    f.write_text(text)
    code, _, err = run(capsys, argv[0], f, *argv[1:])
    line = one_line(err)
    assert code == 2 and line.startswith(f"lago-cvx: error: {f}: ") and fragment in line and line.count(str(f)) == 1
