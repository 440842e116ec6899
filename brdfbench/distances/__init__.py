"""Distances between materials and between their renders, over whole sets: what the set
metrics and the generation harness are computed from, and the image comparisons they use."""
