"""Models: the parameter set, the free-motion model, the driven joint's positional error, the parameter transforms."""
