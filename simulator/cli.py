"""The ``selfalign`` command: one subcommand per module in :mod:`simulator.commands`.

Each command module defines ``register(subparsers)``, which adds its parser and sets
``func`` to a function ``run(args) -> int``. Every failure is one line on stderr:
errors a user can fix (:class:`foundation.InputError`, a full disk, memory) exit
with code 2; anything unexpected says "internal error", where its traceback was saved
(``SELFALIGN_DEBUG=1`` prints it instead) and exits with code 1. SIGTERM and Ctrl-C
leave no temporary file or directory behind (Ctrl-C unwinds; SIGTERM removes the
temporaries and ends the process at once).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import os
import re
import signal
import sys
import tempfile
import threading
import traceback
import warnings

from foundation import InputError, hold

#: Subcommands, in the order ``selfalign --help`` lists them.
COMMANDS = (
    "pattern",
    "energy",
    "simulate",
    "montecarlo",
    "evaluate",
    "sweep",
    "design",
    "calibrate",
    "liquid",
    "demo",
)


#: A value that begins with a minus sign and is made of numbers: a number, or a list of them
#: separated by ``,``, ``:``, ``;``, ``x`` or spaces (``-300,200,10``, ``-100:100:50,-100:100:50``,
#: ``-1e-3``, ``"-100,-100;100,-100;0,100"``). argparse takes such a word for a value, not an option.
NEGATIVE_VALUE = re.compile(r"^-\.?\d[\d.eE+\-,:;x\s]*$")


class OneLineParser(argparse.ArgumentParser):
    """Usage errors as one line (the command and the fix), exit code 2.

    A value with a leading minus sign may follow its flag after a space (``--start
    -300,200,10``, ``--grid -100:100:50,0``, ``--from -60``): argparse's own test for
    negative numbers accepts only a plain number, so it is widened to the numbers and
    number lists the flags take (:data:`NEGATIVE_VALUE`). No option looks like a negative
    number, so argparse keeps treating such words as values.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_VALUE

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_args(self, args=None, namespace=None):  # type: ignore[override]
        """As argparse's, but an unknown option is said by the subcommand it was given to,
        with the nearest of that subcommand's options (``did you mean --chip-size?``) and a
        pointer at the subcommand's ``--help``."""
        namespace, extras = self.parse_known_args(args, namespace)
        if extras:
            sub = self._subcommand(namespace)
            if sub is None:
                self.error(f"unrecognized arguments: {' '.join(extras)}")
            sub.error(unknown_options_message(sub, extras))
        return namespace

    def _subcommand(self, namespace) -> argparse.ArgumentParser | None:
        """The parser of the subcommand ``namespace`` ran (its deepest one: ``pattern four-pad``)."""
        parser: argparse.ArgumentParser | None = None
        actions = self._subparsers._group_actions if self._subparsers else []
        for action in actions:
            if isinstance(action, argparse._SubParsersAction):
                parser = action.choices.get(getattr(namespace, action.dest, None) or "")
        if parser is None:
            return None
        for action in parser._actions:  # a subcommand of its own (pattern DESIGN)
            if isinstance(action, argparse._SubParsersAction):
                deeper = action.choices.get(getattr(namespace, action.dest, None) or "")
                if deeper is not None:
                    return deeper
        return parser


def unknown_options_message(parser: argparse.ArgumentParser, extras: list[str]) -> str:
    """``unrecognized arguments: ...`` and, for a misspelled option, the nearest of
    ``parser``'s options (difflib, as the scene files' keys)."""
    import difflib

    options = [o for o in parser._option_string_actions if o.startswith("--")]
    hints = []
    for word in extras:
        if word.startswith("-") and not NEGATIVE_VALUE.match(word):
            name = word.split("=", 1)[0]
            near = difflib.get_close_matches(name, options, n=1, cutoff=0.6)
            if near:
                hints.append(f"did you mean {near[0]}?")
    return f"unrecognized arguments: {' '.join(extras)}" + (f"; {' '.join(hints)}" if hints else "")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand, or of ``command`` alone when it names one: a command
    then imports its own module only (the others' imports cost 0.1 s before every run)."""
    parser = OneLineParser(
        prog="selfalign",
        description="Capillary self-alignment of microchips: patterns, energy landscapes, trajectories.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in (command,) if command in COMMANDS else COMMANDS:
        importlib.import_module(f"simulator.commands.{name}").register(sub)
    return parser


#: OS errors a user can fix (disk full, quota, read-only or forbidden place): exit 2.
USER_OS_ERRORS = {
    errno.ENOSPC,
    errno.EDQUOT,
    errno.EFBIG,
    errno.EROFS,
    errno.EACCES,
    errno.EPERM,
    errno.ENAMETOOLONG,
}


@contextlib.contextmanager
def _boundary():
    """SIGTERM ends the process after removing temporary outputs; library warnings are
    one line each; for one command."""

    def terminate(signum, frame):
        # End at once: unwinding an exception raised at an arbitrary point (inside a lock,
        # a thread pool's shutdown, an XLA call) can hang. Temporaries are removed here;
        # os.write, not print: the main thread may be inside a write to stderr.
        from foundation import remove_pending

        remove_pending()
        os.write(2, b"selfalign: terminated (no partial output was kept)\n")
        os._exit(143)

    def one_line(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        print(f"selfalign: warning: {text}", file=sys.stderr)

    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, terminate) if main_thread else None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            warnings.simplefilter(
                "ignore", ResourceWarning
            )  # files a failed library write left open
            warnings.showwarning = one_line
            yield
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


def _quiet_stdout() -> None:
    """After stdout failed: point it at /dev/null so the interpreter's final flush is silent."""
    with contextlib.suppress(Exception):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())


def _internal_error(command: str, err: BaseException) -> int:
    """One line naming the failure and where its traceback is; the traceback in a file."""
    text = "".join(traceback.format_exception(err))
    where = "set SELFALIGN_DEBUG=1 to see the traceback"
    with contextlib.suppress(OSError):
        fd, name = tempfile.mkstemp(prefix="selfalign-traceback-", suffix=".txt")
        with os.fdopen(fd, "w") as f:
            f.write(text)
        where = f"traceback in {name}, or set SELFALIGN_DEBUG=1 to print it"
    summary = " ".join(f"{type(err).__name__}: {err}".split())[:300]
    print(
        f"selfalign {command}: internal error: {summary} ({where}); please report it",
        file=sys.stderr,
    )
    return 1


#: NumPy's hugepage advice for the command's process (``NUMPY_MADVISE_HUGEPAGE``; a value
#: the user set is kept). NumPy marks every array of 4 MB or more for transparent hugepages
#: where the kernel leaves them to ``madvise`` (the default of most distributions); on the
#: virtual machines measured (2-core x86-64, ``transparent_hugepage/enabled`` and
#: ``defrag`` both ``madvise``) the first write to such an array cost about 1.3 s of kernel
#: time per 0.5 GB against 0.1 s without the advice, later ones nothing either way
#: (numpy/numpy#31590 describes the stall). A footprint run writes its pads' planes once:
#: without the advice the benchmark's batch took 5.8-6.0 s instead of 5.7-6.8 s, its bench
#: run 12.6-12.8 s instead of 14.4-14.7 s, a stateless run the same (docs/benchmarks.md).
HUGEPAGE_ADVICE = "0"


def _numpy_hugepages() -> None:
    """Set :data:`HUGEPAGE_ADVICE` for NumPy, read when NumPy is first imported: only where
    it is not imported yet (the command's own process, not a caller that imported it) and
    the user set no value."""
    if "numpy" not in sys.modules:
        os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", HUGEPAGE_ADVICE)


def main(argv: list[str] | None = None) -> int:
    _numpy_hugepages()
    with _boundary():
        name = "command"
        try:
            hold("startup")
            argv = sys.argv[1:] if argv is None else list(argv)
            parser = build_parser(argv[0] if argv else None)
            args = parser.parse_args(argv)
            name = args.command
            from foundation import quiet_waits

            with quiet_waits(
                bool(getattr(args, "quiet", False))
            ):  # --quiet also silences the engine's waiting lines
                code = int(args.func(args) or 0)
            sys.stdout.flush()
            return code
        except InputError as err:
            print(f"selfalign {name}: error: {err}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("selfalign: interrupted (no partial output was kept)", file=sys.stderr)
            return 130
        except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
            _quiet_stdout()
            sys.stderr.close()
            return 141
        except MemoryError:
            print(
                f"selfalign {name}: error: out of memory; lower --memory-budget, use a coarser --resolution or fewer starts",
                file=sys.stderr,
            )
            return 2
        except RecursionError:
            print(
                f"selfalign {name}: error: an input is nested too deeply to read; simplify it",
                file=sys.stderr,
            )
            return 2
        except OSError as err:
            if os.environ.get("SELFALIGN_DEBUG") == "1" or err.errno not in USER_OS_ERRORS:
                if os.environ.get("SELFALIGN_DEBUG") == "1":
                    raise
                return _internal_error(name, err)
            target = err.filename or "standard output"
            if target == "standard output":
                _quiet_stdout()
            print(
                f"selfalign {name}: error: cannot write {target}: {err.strerror}; free some space or choose another place "
                "(no partial output was kept)",
                file=sys.stderr,
            )
            return 2
        except Exception as err:
            if os.environ.get("SELFALIGN_DEBUG") == "1":
                raise
            if "RESOURCE_EXHAUSTED" in str(err):
                print(
                    f"selfalign {name}: error: out of memory on the accelerator; lower --memory-budget or use a coarser --resolution",
                    file=sys.stderr,
                )
                return 2
            return _internal_error(name, err)


if __name__ == "__main__":
    raise SystemExit(main())
