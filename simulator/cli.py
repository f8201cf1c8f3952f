"""The ``selfalign`` command: one subcommand per module in :mod:`simulator.commands`.

Each command module defines ``register(subparsers)``, which adds its parser and sets
``func`` to a function ``run(args) -> int``. Errors a user can fix
(:class:`patterns.errors.InputError`) print one line and exit with code 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from patterns.errors import InputError

#: Subcommands, in the order ``selfalign --help`` lists them.
COMMANDS = ("pattern", "energy", "simulate", "montecarlo", "evaluate", "demo")


class OneLineParser(argparse.ArgumentParser):
    """Usage errors as one line (the command and the fix), exit code 2."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="selfalign",
        description="Capillary self-alignment of microchips: patterns, energy landscapes, trajectories.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(f"simulator.commands.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except InputError as err:
        print(f"selfalign {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("selfalign: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        sys.stderr.close()
        return 141


if __name__ == "__main__":
    raise SystemExit(main())
