"""Study subcommands of the ``hybmss`` command."""

from __future__ import annotations


def register(sub) -> None:
    """Add the study subcommands (``compare``, ...) to the ``hybmss`` parser."""
