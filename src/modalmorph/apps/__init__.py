"""The applications: the command line (:mod:`.cli`), what one run does (:mod:`.runs`),
batches (:mod:`.batch`), the web app (:mod:`.app`) and the HTML report (:mod:`.report`).
Nothing below this package imports it."""

import sys


def main(argv: list[str] | None = None) -> int:
    """The ``modalmorph`` command (:func:`modalmorph.apps.cli.main`); ``--version``
    answers without loading the numerics."""
    args = sys.argv[1:] if argv is None else list(argv)
    if args == ["--version"]:
        from ..version import __version__

        print(f"modalmorph {__version__}")
        return 0
    from .cli import main as run

    return run(args)
