"""Identification: motion-capture datasets, the fitting problem, the fit and its report."""
