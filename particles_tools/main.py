"""The ``particles`` console command: the command line of :mod:`.cli` with every subcommand,
``particles wedge`` included (the wedge's workers call :func:`.cli.main` for ``particles run``, so
the wedge is added here rather than imported by the command line itself)."""
import gc

from . import cli
from .wedge import add_parser as add_wedge_parser


def main(argv=None) -> int:
    return cli.main(argv, extra=(add_wedge_parser,))


def console() -> int:
    """:func:`main` as the process itself (the ``particles`` script, ``python -m engine``): its
    exit code. What the command made is then left to the process's end: ``gc.freeze`` moves every
    object out of the collector's reach, so the interpreter's final collections, which would walk
    every object the imports and Taichi's front end left (~82,000 for sparks), have none to walk; objects are
    still freed by reference count, files closed, exit handlers run (the offline cache written:
    ``engine.runtime``). ~70 ms of a warm ``particles run … --frames 1``. A host that calls
    :func:`main` keeps its collector as it was."""
    code = main()
    gc.freeze()
    return code
