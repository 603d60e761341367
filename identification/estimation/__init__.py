"""Estimation: the data class, the fit metric and results, least squares, NSGA-II, uncertainty."""
