"""Long mutation-fuzzing run of the pose-graph reader and the CLI (for developers, not CI).

Same mutator and oracles as ``tests/test_fuzz.py`` (they live in ``tests/fuzzing.py``)::

    python tests/fuzz_long.py                          # 20 000 mutants, seed 0
    python tests/fuzz_long.py --iterations 100000 --seed 7 --cli-every 10
    python tests/fuzz_long.py --no-real                # synthetic seeds only

Run it as a script: Python puts the script's folder, ``tests/``, first on the module search path,
so the mutator is imported as ``fuzzing`` with no path manipulation. pytest does not collect this
file (its name does not start with ``test_``).

Every mutant goes through ``read_graph`` (contract: a ``PoseGraph`` that survives write → read, or a
well-formed ``ParseError``); every ``--cli-every``-th also through ``lago-cvx info`` and ``lago-cvx
solve`` (exit status 0 or 2). Prints a summary table per mutation and per outcome. Every unexpected
outcome (any other exception, a broken ``ParseError`` contract, exit status 1, an exception escaping
``main``, a call slower than ``--time-limit`` seconds) is saved — mutant bytes plus a ``.txt`` with
the mutations, the seed file and the traceback — in ``--out`` (at most ``--keep`` per signature).
Warnings raised by the library (e.g. numpy ``RuntimeWarning``) and "successful" runs printing
NaN/Infinity are counted and listed; they are not failures. The five slowest calls are listed too.
Exit status: 0 if nothing unexpected happened, 1 otherwise.

Bugs it found (regression tests in ``tests/test_fuzz.py``): exit 1 on a one-pose file and on badly
scaled information, non-JSON output (NaN/Infinity), silent garbage for huge angles, and reads taking
minutes (quadratic regex on a long digit run followed by a stray byte: with seed 0, five of 20 000
mutants, e.g. 6159 and 8635, took 80–143 s each before the fix).
"""

from __future__ import annotations

import argparse
import logging
import random
import shutil
import sys
import tempfile
import time
from pathlib import Path

from lago_cvx.datasets import datasets_dir

import fuzzing  # tests/fuzzing.py, beside this script


def _signature(detail: str) -> str:
    """A short key grouping unexpected outcomes with the same cause (last traceback line / message)."""
    lines = [ln.strip() for ln in detail.strip().splitlines() if ln.strip()]
    key = lines[-1] if lines else detail
    return key[:160]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--iterations", type=int, default=20000, help="number of mutants (default 20000)")
    p.add_argument("--seed", type=int, default=0, help="seed of random.Random (default 0)")
    p.add_argument("--cli-every", type=int, default=20,
                   help="run the CLI (info and solve) on every k-th mutant; 0 disables (default 20)")
    p.add_argument("--no-real", action="store_true", help="synthetic seeds only (no datasets)")
    p.add_argument("--max-stack", type=int, default=3, help="at most this many stacked mutations (default 3)")
    p.add_argument("--out", default="fuzz_reproducers", help="folder for reproducers (default ./fuzz_reproducers)")
    p.add_argument("--keep", type=int, default=3, help="reproducers kept per distinct signature (default 3)")
    p.add_argument("--time-limit", type=float, default=5.0,
                   help="a read or CLI call slower than this (seconds) counts as unexpected (default 5)")
    p.add_argument("--roundtrip", action=argparse.BooleanOptionalAction, default=True,
                   help="check write → read of every parsed mutant (default on)")
    args = p.parse_args(argv)

    # The CLI's logging.basicConfig is a no-op once the root logger has a handler: keep LAGO's
    # warnings (e.g. ambiguous regularization on mangled graphs) out of the report.
    logging.basicConfig(level=logging.ERROR, format="%(name)s: %(levelname)s: %(message)s")

    work = Path(tempfile.mkdtemp(prefix="lago_fuzz_"))
    try:
        return _run(args, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)  # the reproducers worth keeping are in --out


def _run(args, work: Path) -> int:
    seeds = fuzzing.synthetic_seeds(work / "seeds")
    if not args.no_real:
        ddir = datasets_dir()  # $LAGO_CVX_DATASETS, then ../shared/datasets (lago_cvx.datasets)
        found = {} if ddir is None else {rel: ddir / rel for rel, _ in fuzzing.REAL_SEED_FILES
                                         if (ddir / rel).is_file()}
        seeds.update(fuzzing.real_seeds(found))
        if len(found) < len(fuzzing.REAL_SEED_FILES):
            where = "the datasets folder (not found)" if ddir is None else ddir
            print(f"note: {len(fuzzing.REAL_SEED_FILES) - len(found)} real seed file(s) not found under {where}")
    names = sorted(seeds)
    print(f"{len(names)} seed files: {', '.join(names)}")
    print(f"{args.iterations} mutants, seed {args.seed}, CLI on every {args.cli_every or '—'}th")

    rng = random.Random(args.seed)
    read, cli = fuzzing.Tally(), fuzzing.Tally()
    out_dir = Path(args.out)
    saved: dict = {}
    slowest: list = []  # (seconds, stage, mutant index, seed file, mutations)
    t0 = time.perf_counter()
    rt_dir = work / "roundtrip"
    rt_dir.mkdir()

    def save(i, stage, name, mutations, detail, data):
        sig = f"slow {stage} (> --time-limit)" if detail.startswith("slow:") else _signature(detail)
        n = saved.get(sig, 0)
        saved[sig] = n + 1
        if n >= args.keep:
            return
        out_dir.mkdir(parents=True, exist_ok=True)
        stem = out_dir / f"seed{args.seed}-{i:06d}-{stage}"
        stem.with_suffix(".g2o").write_bytes(data)
        stem.with_suffix(".txt").write_text(
            f"mutant {i} (random.Random({args.seed}), {stage})\nseed file: {name}\nmutations: {mutations}\n"
            f"reproduce: {stem.with_suffix('.g2o')}\n\n{detail}\n", encoding="utf-8")
        print(f"  UNEXPECTED [{stage}] mutant {i} from {name} {mutations}: {sig}\n    saved {stem}.g2o/.txt")

    for i in range(args.iterations):
        name = names[i % len(names)]
        data, mutations = fuzzing.mutate(seeds[name], rng, max_stack=args.max_stack)
        path = work / f"mutant-{i % 100:02d}.g2o"
        path.write_bytes(data)
        outcome = fuzzing.check_read(path, roundtrip_dir=rt_dir if args.roundtrip else None,
                                     time_limit=args.time_limit)
        read.add(outcome, mutations, name, data)
        slowest.append((outcome.seconds, "read_graph", i, name, mutations))
        if outcome.kind == "unexpected":
            save(i, "read_graph", name, mutations, outcome.detail, data)
        if args.cli_every and i % args.cli_every == 0:
            for command in ("info", "solve"):
                outcome = fuzzing.check_cli(path, command, time_limit=args.time_limit)
                cli.add(outcome, mutations, f"{command} {name}", data)
                slowest.append((outcome.seconds, command, i, name, mutations))
                if outcome.kind == "unexpected":
                    save(i, command, name, mutations, outcome.detail, data)
        if len(slowest) > 200:
            slowest = sorted(slowest, reverse=True)[:10]
        if (i + 1) % 5000 == 0:
            print(f"  ... {i + 1} mutants, {time.perf_counter() - t0:.1f} s, "
                  f"{read.get('unexpected') + cli.get('unexpected')} unexpected")
    elapsed = time.perf_counter() - t0

    _print_table(read, cli)
    print(f"\nread_graph: {read.total} inputs, {read.get('parsed')} parsed, {read.get('parse_error')} ParseError, "
          f"{read.get('unexpected')} unexpected")
    if cli.total:
        print(f"CLI: {cli.total} runs, {cli.get('exit0')} exit 0, {cli.get('exit2')} exit 2, "
              f"{cli.get('unexpected')} unexpected")
    for title, tally in (("read_graph", read), ("CLI", cli)):
        for text, (count, label, _) in sorted(tally.warnings.items(), key=lambda kv: -kv[1][0]):
            print(f"warning ({title}) x{count}: {text}  (first from {label})")
    print("\nslowest calls (the mutant is reproducible from --seed and its index):")
    for sec, stage, i, name, mutations in sorted(slowest, reverse=True)[:5]:
        print(f"  {sec:8.3f} s  {stage:10s} mutant {i} from {name} {mutations}")
    if saved:
        print("\nunexpected outcomes by signature:")
        for sig, count in sorted(saved.items(), key=lambda kv: -kv[1]):
            print(f"  {count:6d}  {sig}")
        print(f"reproducers in {out_dir.resolve()}")
    print(f"\n{elapsed:.1f} s ({1000 * elapsed / max(args.iterations, 1):.2f} ms per mutant)")
    return 1 if saved else 0


def _print_table(read: fuzzing.Tally, cli: fuzzing.Tally) -> None:
    cols = [("parsed", read), ("parse_error", read), ("unexpected", read),
            ("exit0", cli), ("exit2", cli), ("unexpected", cli)]
    head = ["mutation", "parsed", "ParseError", "unexpected", "cli 0", "cli 2", "cli unexp."]
    rows = []
    for name in sorted(set(read.by_mutation) | set(cli.by_mutation)):
        rows.append([name] + [str(t.by_mutation.get(name, {}).get(k, 0)) for k, t in cols])
    rows.append(["TOTAL (inputs)"] + [str(t.get(k)) for k, t in cols])
    widths = [max(len(r[c]) for r in rows + [head]) for c in range(len(head))]
    fmt = "  ".join(f"{{:<{widths[0]}}}" if c == 0 else f"{{:>{widths[c]}}}" for c in range(len(head)))
    print()
    print(fmt.format(*head))
    print(fmt.format(*("-" * w for w in widths)))
    for r in rows:
        print(fmt.format(*r))
    print("(a mutant counts once under each mutation it applied; CLI columns count info and solve runs)")


if __name__ == "__main__":
    sys.exit(main())
