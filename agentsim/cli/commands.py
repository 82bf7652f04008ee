"""The parser of every command that does one piece of work (all but ``agentsim sweep``), in a module of
its own so that the command line (:mod:`agentsim.cli`) and the sweep, which runs these commands as the
points of a grid, both build the same parser without importing each other."""

from __future__ import annotations

import argparse

PROG = "agentsim"
DESCRIPTION = "A BML realizer on a discrete-event clock."


class Parser(argparse.ArgumentParser):
    """The parser of every command and subcommand: a usage error is one line on stderr (``agentsim eval
    speech-sync: error: argument --seed: a seed is a whole number from 0, got -1``), exit status 2, as every
    other error is one line; ``--help`` shows the usage."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def add_parsers(commands) -> None:
    """Add the work commands to the subparsers ``commands``; each sets its ``handler``."""
    from agentsim.cli import beats, realize, scenarios, serve, speech

    realize.add_parsers(commands)
    beats.add_parsers(commands)
    speech.add_parsers(commands)
    scenarios.add_parsers(commands)
    serve.add_parsers(commands)


def build_parser() -> argparse.ArgumentParser:
    """The parser of the work commands alone; each command's ``handler`` (set with ``set_defaults``) runs it."""
    parser = Parser(prog=PROG, description=DESCRIPTION)
    add_parsers(parser.add_subparsers(dest="command", required=True))
    return parser
