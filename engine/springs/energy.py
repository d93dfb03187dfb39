"""Energy of a spring network, computed in float64 numpy from the state (deterministic order).

kinetic ½ Σ m|v|² over free nodes, gravitational −Σ m g·x over free nodes, spring ½ Σ ks(|L| − r)²;
``total`` is their sum. Pinned nodes are driven from outside and carry no energy of their own.
"""
from __future__ import annotations

import csv
from typing import Iterable, Mapping

import numpy as np

FIELDS = ("t", "kinetic", "gravitational", "spring", "total")


def network_energy(top, pinned_mask: np.ndarray, x: np.ndarray, v: np.ndarray, gravity) -> dict:
    x = np.asarray(x, np.float64)
    v = np.asarray(v, np.float64)
    m = np.where(pinned_mask, 0.0, top.masses)
    kinetic = 0.5 * float(np.sum(m * np.einsum("ij,ij->i", v, v)))
    grav = -float(np.sum(m * (x @ np.asarray(gravity, np.float64))))
    if len(top.edges):
        stretch = np.linalg.norm(x[top.edges[:, 0]] - x[top.edges[:, 1]], axis=1) - top.rest_length
        spring = 0.5 * float(np.sum(top.ks * stretch * stretch))
    else:
        spring = 0.0
    return dict(kinetic=kinetic, gravitational=grav, spring=spring, total=kinetic + grav + spring)


def write_energy_csv(path, rows: Iterable[Mapping]) -> None:
    """Write energy rows (dicts with keys of :data:`FIELDS`) as CSV with a header line."""
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: repr(float(r[k])) if k in r else "" for k in FIELDS})
