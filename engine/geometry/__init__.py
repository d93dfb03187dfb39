"""Geometry shared by every kind of physics: shapes (plane, sphere, box, capsule) with their signed
distance, closest point, outward normal and mass properties, and poses that translate and rotate
(:mod:`.shapes`); the deterministic neighbour grid (:mod:`.grid`) and its Taichi-free size
estimate (:mod:`.sizing`, what the config checks before anything is allocated); the colour
schedule of elements that share nodes (:mod:`.colouring`).

Imports no physics room (particles, springs, rigid): the shape table (:mod:`engine.colliders`),
the interacting particles and the rigid bodies build on it."""

# No re-exports: the config imports .sizing (no Taichi) and must not load .shapes (Taichi) with it.
