"""Geometry shared by every system: the deterministic neighbour grid (:mod:`.grid`) and its
Taichi-free size estimate (:mod:`.sizing`, what the config checks before anything is allocated)."""
