"""The ``hybmss`` command: its parser and contract (:mod:`.parser`) and what each subcommand does
(:mod:`.commands`, :mod:`.modes`).  The top floor: it imports the others, none imports it."""

from studies.cli.parser import main

__all__ = ["main"]
