"""Forces for every kind of physics: fields that act on any point mass (:mod:`.fields`: gravity,
linear drag toward the wind, attractors, vortices), read by particles and spring nodes alike;
interaction terms defined once (:mod:`.terms`: energy, gradient, constraint form) and the element
groups that evaluate them over a soft body's elements (:mod:`.elements`)."""
