"""brdfbench: benchmark and evaluation framework for BRDF representations and generators."""

__version__ = "0.1.0"
