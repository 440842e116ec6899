"""Packaged Hydra configs (import name `brdfbench_conf`)."""
