"""The ``particles`` console command: the command line of :mod:`.cli` with every subcommand,
``particles wedge`` included (the wedge's workers call :func:`.cli.main` for ``particles run``, so
the wedge is added here rather than imported by the command line itself)."""
from . import cli
from .wedge import add_parser as add_wedge_parser


def main(argv=None) -> int:
    return cli.main(argv, extra=(add_wedge_parser,))
