"""Fitting: the Levenberg–Marquardt engine, start grids, the free/driven/batch fits and the analysis at the optimum."""
