"""The ``motorid`` command line: the parser built from an explicit list of commands.

Every user error becomes one line on stderr and exit status 2; no traceback.

Adding a command is one line in :data:`COMMANDS`: a module of :mod:`motorid.cli`
with ``register(sub)`` (adds its subparser and ``set_defaults(func=run)``) and
``run(args) -> int``, a thin layer over a library function.  Command modules
import the library inside ``run``, so building the parser stays light.
"""

from __future__ import annotations

import argparse
import os
import sys

from motorid.cli import demo, diagnose, export, fit, fleet, plan, predict, report, ripple_table, simulate
from motorid.errors import InputError

#: the commands, in the order ``motorid --help`` lists them
COMMANDS = (
    ripple_table,
    simulate,
    fit,
    predict,
    report,
    diagnose,
    plan,
    fleet,
    export,
    demo,
)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="motorid", description="The ``motorid`` command line.")
    p.add_argument("--quiet", "-q", dest="quiet_all", action="store_true",
                   help="no progress bars (they show only on a terminal anyway)")
    sub = p.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.register(sub)
    for name, command_parser in sub.choices.items():  # every command takes --quiet too
        if not any("--quiet" in a.option_strings for a in command_parser._actions):
            command_parser.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from motorid.progress import set_quiet

    set_quiet(args.quiet_all or getattr(args, "quiet", False))
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"motorid {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"motorid {args.command}: interrupted", file=sys.stderr)
        return 130


class _PipeSafe:
    """Standard output that goes quiet once its reader has gone (``motorid fit … | head``): the
    command still writes its files, and no BrokenPipeError traceback is printed."""

    def __init__(self, stream):
        self.stream, self.broken = stream, False

    def write(self, text):
        if not self.broken:
            try:
                return self.stream.write(text)
            except BrokenPipeError:
                self.broken = True
        return len(text)

    def flush(self):
        if not self.broken:
            try:
                self.stream.flush()
            except BrokenPipeError:
                self.broken = True

    def __getattr__(self, name):
        return getattr(self.stream, name)


def console() -> None:
    """The ``motorid`` command: :func:`main`, then a prompt exit.

    Everything is written and closed by then; ``os._exit`` skips the interpreter's
    teardown of JAX and XLA (a fifth of a second that the user would wait for nothing).
    """
    sys.stdout = _PipeSafe(sys.stdout)
    rc = main()
    points = sys.modules.get("motorid.identify.log_points")
    if points is not None:  # the temporary points of logs without a shaft angle (exit handlers skipped)
        points.remove_temporary_folders()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)


if __name__ == "__main__":
    console()
