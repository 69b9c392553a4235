"""``lago-cvx``: the parser and the one place where errors become exit statuses."""

from __future__ import annotations

import argparse
import errno
import logging
import os
import sys

from .._version import __version__
from ..errors import GraphError, LagoError, OutputError
from . import certify, data, plot, solve, worlds
from .common import EXIT_INTERNAL, EXIT_OK, EXIT_TABLE, debug_enabled, speak_cli, stdout_error
from .startup import defer_unused_numpy_modules

log = logging.getLogger("lago_cvx")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lago-cvx", description="LAGO for planar and 3-D pose graphs (g2o / TORO files).",
                                epilog=EXIT_TABLE)
    p.add_argument("--version", action="version", version=f"lago-cvx {__version__}")
    p.add_argument("-v", "--verbose", action="count", default=0, help="log progress (-vv for debug)")
    sub = p.add_subparsers(dest="command", required=True)
    solve.add_parsers(sub)
    certify.add_parser(sub)
    worlds.add_parsers(sub)
    data.add_parser(sub)
    plot.add_parser(sub)
    for command in sub.choices.values():  # -v also after the command: lago-cvx solve FILE -v
        command.add_argument("-v", "--verbose", action="count", default=0, dest="verbose_after",
                             help="log progress (-vv for debug)")
    return p


def _subcommands(parser: argparse.ArgumentParser) -> dict:
    """{command name: its parser}."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices
    return {}


def unrecognized_hint(parser: argparse.ArgumentParser, command: str, extra: list[str]) -> str:
    """A hint for arguments ``command`` does not take: an option that belongs to other commands (named) or is
    close to one of its own (difflib), or a stray file name where the command writes one with ``-o`` ("did you mean
    -o OUT?"; not a value following an unknown option), or a stray word that is one of the choices of the command's
    options ("did you mean --world manhattan?"). "" when there is none."""
    import difflib

    commands = _subcommands(parser)
    own = commands[command]._option_string_actions
    for k, arg in enumerate(extra):
        if arg.startswith("-") and arg != "-":
            name = arg.split("=", 1)[0]
            owners = [c for c, p in commands.items() if c != command and name in p._option_string_actions]
            if owners:
                return (f" ({name} belongs to `{'`, `'.join(owners)}`, e.g. lago-cvx {owners[0]} FILE {name} …; "
                        f"`lago-cvx {command} --help` lists {command}'s options)")
            close = difflib.get_close_matches(name, [o for o in own if o.startswith("--")], n=1, cutoff=0.8)
            if close:
                return f" (did you mean {close[0]}?)"
        elif k > 0 and extra[k - 1].startswith("-"):
            continue  # the value of an unknown option
        elif choosers := _options_choosing(commands[command], arg):
            return f" (did you mean {' or '.join(f'{o} {arg}' for o in choosers)}?)"
        elif "-o" in own:
            return f" (did you mean -o {arg}? {command} writes its output only where -o names it)"
        else:
            return f" ({command} takes one FILE)"
    return ""


def _options_choosing(command: argparse.ArgumentParser, word: str) -> list[str]:
    """The options of ``command`` (each by its longest name) among whose ``choices`` ``word`` is."""
    return [max(a.option_strings, key=len) for a in command._actions
            if a.option_strings and a.choices is not None and not isinstance(a, argparse._SubParsersAction)
            and word in {str(c) for c in a.choices}]


class _CliMessages(logging.Filter):
    """Log records as a CLI user reads them: library keywords become options (``speak_cli``), and each
    distinct warning is said once per run (library loops may repeat one)."""

    def __init__(self):
        super().__init__()
        self.seen = set()

    def filter(self, record):
        record.msg, record.args = speak_cli(record.getMessage()), ()
        if record.levelno < logging.WARNING:
            return True
        key = (record.name, record.msg)
        if key in self.seen:
            return False
        self.seen.add(key)
        return True


def _configure_logging(verbose: int) -> None:
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("lago-cvx: %(levelname)s: %(message)s"))
    handler.addFilter(_CliMessages())
    root = logging.getLogger("lago_cvx")
    root.handlers[:] = [handler]
    root.propagate = False
    root.setLevel([logging.WARNING, logging.INFO, logging.DEBUG][min(verbose, 2)])


def _reader_left(exc: BaseException) -> bool:
    """True when ``exc`` says standard output's reader has gone (EPIPE: ``lago-cvx … | head -1``), as a
    ``BrokenPipeError`` from ``print`` or an ``OutputError`` from the estimate's writer."""
    return isinstance(exc, BrokenPipeError) or (isinstance(exc, OutputError) and exc.errno == errno.EPIPE)


def _quiet_stdout() -> int:
    """End quietly, as ``cat`` does when its reader leaves: standard output's descriptor is pointed at
    the null device, so that the interpreter's final flush of what is still buffered cannot fail with a
    message. (A caller's in-process stand-in without a descriptor is left alone.) Returns ``EXIT_OK``."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, OSError):
        return EXIT_OK
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
    finally:
        os.close(devnull)
    return EXIT_OK


def main(argv=None) -> int:
    """Run one ``lago-cvx`` command; ``argv=None`` means the process's own command line.

    Only then (the console entry point) are NumPy's unused submodules made lazy before SciPy loads
    (:mod:`lago_cvx.cli.startup`), and is the sparse engine asked to hold the BLAS to one thread while it factors
    (``sparse.engine_threads(blas_threads=1)``: the process is the command's own, and OpenBLAS's threads cost far
    more than they give on the engine's small dense blocks when the other cores are busy, ``benchmarks/million.md``);
    an in-process caller passing ``argv`` keeps its import state and its BLAS settings.
    A standard output closed by its reader ends the command quietly with status 0 (``_quiet_stdout``).
    """
    if argv is None:
        defer_unused_numpy_modules()
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # the command's own usage, with a hint (unrecognized_hint), instead of the top level's
        command = _subcommands(parser)[args.command]
        command.error(f"unrecognized arguments: {' '.join(extra)}{unrecognized_hint(parser, args.command, extra)}")
    _configure_logging(args.verbose + getattr(args, "verbose_after", 0))
    try:
        import numpy as np

        from ..sparse import engine_threads

        with np.errstate(all="ignore"), engine_threads(blas_threads=1 if argv is None else None):
            status = args.func(args)  # overflow is reported as a non-finite estimate, not a warning
        if sys.stdout is not None:  # (None: started without a standard output)
            try:
                sys.stdout.flush()  # a reader that left shows here, not in the interpreter's final flush
            except BrokenPipeError:
                raise
            except OSError as exc:  # a full disk behind standard output
                raise stdout_error(exc) from None
        return status
    except LagoError as exc:  # everything the package reports on purpose; the class carries the status
        if _reader_left(exc):
            return _quiet_stdout()
        if isinstance(exc, OutputError) and exc.path == "-":  # what is still buffered cannot be written either
            _quiet_stdout()
        if exc.exit_status == EXIT_INTERNAL and debug_enabled():
            raise
        prefix = "internal error" if exc.exit_status == EXIT_INTERNAL else "error"
        message = speak_cli(str(exc))
        source = getattr(args, "file", None)
        if isinstance(exc, GraphError) and source and str(source) not in message:  # the graph read: name its file
            message = f"{source}: {message}"
        print(f"lago-cvx: {prefix}: {message}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        print("lago-cvx: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `lago-cvx info f --json | head -c1`: the reader left; not an error of ours
        return _quiet_stdout()
    except Exception as exc:  # an internal error: one line, exit 1 (traceback with LAGO_CVX_DEBUG=1)
        if debug_enabled():
            raise
        print(f"lago-cvx: internal error: {type(exc).__name__}: {exc} "
              "(set LAGO_CVX_DEBUG=1 for a traceback)", file=sys.stderr)
        return EXIT_INTERNAL
