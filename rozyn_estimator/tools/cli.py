"""``rozyn``: the command line, a registry of commands imported only when invoked.

Each command (:data:`COMMANDS`) is a name, a one-line help and the module that
implements it, ``rozyn_estimator.tools.<module>``, which defines ``DESCRIPTION``,
``add_arguments(parser)`` and ``run(args) -> int``. The top-level parser lists the
commands from the registry alone; the module of the command invoked (or asked for
``--help``) is imported, and its options added, when argparse selects it. So
``rozyn --help`` imports nothing but this module, and ``rozyn trial`` no ROS.

Errors a user can act on (bad options, files, bags) print one line to stderr and exit
with status 1; usage errors exit with 2 (argparse); Ctrl-C exits with 130.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Any

from rozyn_estimator.errors import RozynError

PACKAGE = "rozyn_estimator.tools"


@dataclass(frozen=True)
class Command:
    """A ``rozyn`` command: its name, its line in ``rozyn --help`` and its module."""

    name: str
    help: str  # as argparse takes it: a literal % is written %%
    module: str  # under rozyn_estimator.tools: DESCRIPTION, add_arguments(parser), run(args) -> int

    def load(self) -> ModuleType:
        return importlib.import_module(f"{PACKAGE}.{self.module}")


# In the order ``rozyn --help`` lists them.
COMMANDS = (
    Command("trial", "simulate seeded runs and estimate from each", "trial.command"),
    Command("demo", "the main job: sim and estimator nodes on sim time, estimate vs truth", "demo.command"),
    Command("bench", "time the simulator and the pipeline (JSON)", "bench.command"),
    Command("replay", "replay bags through the online estimator offline: CSV of updates + output bag",
            "replay.command"),
    Command("study", "Monte-Carlo grid of the thesis: speed x measurement time x road, tables and plots",
            "study.command"),
    Command("compare", "run several methods on the same seeded runs: bias, std, 95 %% coverage, failures, "
            "time", "compare.command"),
)
_BY_NAME = {c.name: c for c in COMMANDS}


class _Commands(argparse._SubParsersAction):
    """The sub-commands' action: the chosen command's parser gets its options first.

    argparse calls this action with the command's name and the arguments after it,
    before the command's parser parses them (``--help`` included).
    """

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: str | Sequence[Any] | None, option_string: str | None = None) -> None:
        if values:
            name = values if isinstance(values, str) else values[0]
            command, sub = _BY_NAME.get(name), self._name_parser_map.get(name)
            if command is not None and sub is not None and sub.get_default("func") is None:
                _load(command, sub)
        super().__call__(parser, namespace, values, option_string)


def _load(command: Command, parser: argparse.ArgumentParser) -> None:
    """Import the command's module and give its parser the description, options and function."""
    module = command.load()
    parser.description = module.DESCRIPTION
    module.add_arguments(parser)
    parser.set_defaults(func=module.run)


def build_parser() -> argparse.ArgumentParser:
    """The ``rozyn`` parser; a command's options are added when it is invoked."""
    parser = argparse.ArgumentParser(
        prog="rozyn",
        description="Vehicle inertial parameter estimation (Rozyn & Zhang): simulate, estimate, replay.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", action=_Commands)
    for command in COMMANDS:
        sub.add_parser(command.name, help=command.help)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except RozynError as exc:
        print(f"rozyn {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"rozyn {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
