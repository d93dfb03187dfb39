"""Energy of a spring network in float64 (deterministic order).

kinetic ½ Σ m|v|² over free nodes, gravitational −Σ m g·x over free nodes (NumPy), spring
½ Σ ks(|L| − r)² from the Hooke term itself (engine.forces.terms.hooke_energy, summed in a serial
f64 kernel); ``total`` is their sum. Pinned nodes are driven from outside and carry no energy of their own.
"""
from __future__ import annotations

import csv
from typing import Iterable, Mapping

import numpy as np

FIELDS = ("t", "kinetic", "gravitational", "spring", "total")


def network_energy(top, pinned_mask: np.ndarray, x: np.ndarray, v: np.ndarray, gravity, spring: float) -> dict:
    """kinetic and gravitational energy of the free nodes (J, float64 NumPy) with the springs' own
    ``spring`` energy (the Hooke term's, engine.springs.forces.spring_energy)."""
    x = np.asarray(x, np.float64)
    v = np.asarray(v, np.float64)
    m = np.where(pinned_mask, 0.0, top.masses)
    kinetic = 0.5 * float(np.sum(m * np.einsum("ij,ij->i", v, v)))
    grav = -float(np.sum(m * (x @ np.asarray(gravity, np.float64))))
    return dict(kinetic=kinetic, gravitational=grav, spring=spring, total=kinetic + grav + spring)


def write_energy_csv(path, rows: Iterable[Mapping]) -> None:
    """Write energy rows (dicts with keys of :data:`FIELDS`) as CSV with a header line; further
    named terms in the rows (bending, volume, a material, user energies) follow as columns, in the
    order they first appear."""
    rows = list(rows)
    fields = list(FIELDS)
    for r in rows:
        fields += [k for k in r if k not in fields]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: repr(float(r[k])) if k in r else "" for k in fields})
