"""``n2r``: the command line. Each subcommand lives in its own module of this package.

A subcommand module defines ``add_parser(subparsers)``, which registers its parser and sets
``func=run`` (a callable taking the parsed arguments and returning an exit code). Heavy imports
(torch, pycolmap) belong inside ``run`` so ``n2r --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from .. import __version__
from ..errors import N2RError
from ._interrupt import exit_status, interrupt_name, interrupted, sigterm_as_ctrl_c
from ._output import printable, tolerant_streams

#: Subcommand modules, in the order ``n2r --help`` lists them.
COMMANDS: tuple[str, ...] = ("poses", "fit", "import", "render", "info", "demo", "study")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="n2r",
        description="pytest-n2r: fit scene fields from photos and render test views for perception code.",
    )
    parser.add_argument("--version", action="version", version=f"pytest-n2r {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"{__package__}.{name}").add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``n2r`` console script; returns the process exit code (130 after Ctrl-C, 143 after
    SIGTERM, which every command handles as Ctrl-C). Its output never fails for a character the terminal cannot
    show (an ASCII locale, a Windows console): :func:`~._output.tolerant_streams` writes such characters escaped,
    its help and usage errors included."""
    with tolerant_streams():
        parser = build_parser()
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.error("expected a COMMAND: " + ", ".join(COMMANDS) + " (n2r --help describes them)")
        try:
            with sigterm_as_ctrl_c():
                code = _run(args)
        except KeyboardInterrupt:  # a SIGTERM in the instant after the command returned
            code = 130
    return exit_status() if code == 130 else code


def _run(args: argparse.Namespace) -> int:
    """The command's exit code, its errors printed as one line each."""
    try:
        return int(args.func(args) or 0)
    except N2RError as exc:
        print(f"n2r {args.command}: error: {printable(exc)}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, SystemError) as exc:  # a SystemError: Ctrl-C inside a compiled kernel's call back
        if not interrupted(exc):
            raise
        print(f"n2r {args.command}: interrupted" + (" (SIGTERM)" if interrupt_name() == "SIGTERM" else ""),
              file=sys.stderr)
        return 130
    except BrokenPipeError:  # `n2r info ... | head`: the reader left; say nothing more
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - the interpreter flushes it at exit
        return 141
    except OSError as exc:  # the disk filled up, a file vanished: the system's reason, without a traceback
        where = f"{printable(exc.filename)}: " if exc.filename else ""  # none: stdout (`> /dev/full`), an open file
        print(f"n2r {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except MemoryError:
        print(f"n2r {args.command}: error: out of memory (a smaller --size or --downscale needs less)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
