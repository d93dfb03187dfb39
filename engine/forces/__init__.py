"""Forces for every kind of physics: fields that act on any point mass (:mod:`.fields`: gravity,
linear drag toward the wind), read by particles and spring nodes alike."""
