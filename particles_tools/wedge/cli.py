"""The ``particles wedge`` subcommand's arguments (registered by ``particles_tools.main``)."""
from __future__ import annotations

import argparse


def _run(args) -> int:
    from .command import cmd_wedge

    return cmd_wedge(args)


def add_parser(sub) -> argparse.ArgumentParser:
    w = sub.add_parser(
        "wedge", help="render variants of a config over a grid of settings (Dask: this machine or "
                      "a cluster), with an index and a contact sheet",
        description="Render the product of the --set lists (x --seeds) as one folder of PNG frames "
                    "per variant, index.csv and contact_sheet.png.")
    w.add_argument("config")
    w.add_argument("--set", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="a config path and its values, e.g. emitters.0.rate=200,400 or "
                        "forces.gravity=[0,-9.81,0],[0,-4,0]; repeat for a grid")
    w.add_argument("--seeds", type=int, default=None,
                   help="also vary the seed: the config's seed, +1, ... (N seeds per combination)")
    w.add_argument("--frames", type=int, default=None, help="render this many frames per variant")
    w.add_argument("--size", default=None, help="image size WxH, e.g. 640x360")
    w.add_argument("--workers", type=int, default=None,
                   help="local worker processes (default: one per core)")
    w.add_argument("--scheduler", default=None,
                   help="address of a running Dask scheduler (tcp://host:8786) instead of local workers")
    w.add_argument("--out", default=None, help="wedge folder (default renders/<config name>_wedge)")
    w.add_argument("--resume", action="store_true",
                   help="finish a wedge in --out: skip finished variants, continue partial ones")
    w.add_argument("--sheet-frame", type=int, default=None,
                   help="frame shown on the contact sheet (default: each variant's last)")
    w.add_argument("--threads", type=int, default=argparse.SUPPRESS,
                   help="Taichi CPU threads per worker (default: cores / workers)")
    w.add_argument("--arch", default=argparse.SUPPRESS,
                   choices=["cpu", "cuda", "vulkan", "metal", "gpu"],
                   help="Taichi backend of the workers")
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    w.set_defaults(func=_run, no_taichi=True)  # the client needs no Taichi: the workers have it
    return w
