"""``particles wedge``: render many variants of one effect config, on this machine or a Dask cluster.

The variants are the product of the ``--set KEY=V1,V2,...`` lists (× ``--seeds N``), all checked
before anything renders (``spec``). Each variant runs ``particles run``'s own code into its own
folder on a Dask worker (``task``, ``farm``); results land in ``index.csv`` and a contact sheet
(``record``, ``sheet``) on the submitting machine as they arrive; ``--resume`` skips finished
variants. ``cli.add_parser`` registers the subcommand; Dask is imported only when it runs.
"""
from .cli import add_parser

__all__ = ["add_parser"]
