"""The ``hybmss`` command: its parser and contract (:mod:`.parser`), one module per subcommand
(:mod:`.info`, :mod:`.moduli`, :mod:`.bench`, :mod:`.fem`, :mod:`.compare`, :mod:`.modes`,
:mod:`.run`, :mod:`.study`) and what they share (:mod:`.common`, :mod:`.options`).  The top floor:
it imports the others, none imports it."""


def main(argv=None) -> int:
    """The ``hybmss`` console script (:func:`studies.cli.parser.main`), imported when called, so
    that ``python -m studies.cli.parser`` runs the parser module once."""
    from studies.cli.parser import main as run_command

    return run_command(argv)


__all__ = ["main"]
