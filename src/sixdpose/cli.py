"""The ``sixdpose`` console script. Each stage adds its subcommands through a ``register`` function.

Errors a user can fix (bad arguments, missing or corrupt files, an output directory that is not ours)
are the package's :class:`~sixdpose.errors.SixdposeError` subclasses, raised by each stage; this module
alone turns them into one line on stderr and exit status 2. Nothing is written in that case.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .errors import SixdposeError, UserError  # noqa: F401  (UserError: importable from here too)

#: Modules that contribute subcommands, each with ``register(subparsers) -> None``; every parser it
#: adds sets ``func`` (called with the parsed namespace, returns an exit status or None).
COMMAND_MODULES = (
    "sixdpose.assets.cli",
    "sixdpose.generation.cli",
    "sixdpose.datasets.cli",
    "sixdpose.segmentation.cli",
    "sixdpose.registration.cli",
    "sixdpose.pose.cli",
    "sixdpose.evaluation.cli",
)


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one line (``prog: error: ...``), exit status 2."""

    def error(self, message):  # noqa: D102
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every available stage's subcommands."""
    from . import __version__

    parser = _Parser(prog="sixdpose", description="6D pose estimation from RGB-D (paper companion)")
    parser.add_argument("--version", action="version", version=f"sixdpose {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:  # a stage that fails to import is an error, never a missing subcommand
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point: parse ``argv`` and run the chosen subcommand; returns the exit status (2 for a bad
    argument, found while parsing by the option layer, :mod:`sixdpose.options`, or by the command)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # a usage error (one line on stderr, see _Parser), --help or --version
        return e.code if isinstance(e.code, int) else 2
    # the command line as typed, for the provenance of result artifacts (sixdpose.artifacts.results)
    args.command_line = ["sixdpose", *(sys.argv[1:] if argv is None else argv)]
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        rc = args.func(args)
    except (SixdposeError, FileNotFoundError, NotADirectoryError, PermissionError) as e:
        print(f"sixdpose {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"sixdpose {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(rc or 0)


if __name__ == "__main__":  # pragma: no cover
    # run through the package module so exception classes are the ones subcommands raise
    from sixdpose.cli import main as _main

    sys.exit(_main())
