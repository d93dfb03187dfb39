"""Interaction terms defined once (:mod:`.terms`: energy, gradient, constraint form) and the
element groups that evaluate them over a soft body's elements (:mod:`.elements`)."""
