"""Built-in BRDF representation plugins (import name `brdfbench_representations`).

Registered through the `brdfbench.representations` entry-point group, like any third party.
"""
