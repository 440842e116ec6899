"""Plugin discovery: typed entry-point specs and the lazy registry."""
