"""Built-in material generator plugins (import name `brdfbench_generators`).

Generators register in the `brdfbench.generators` entry-point group with a
`brdfbench.specs.GeneratorSpec`; none is built in yet (PCA, VAE and hyperdiffusion
generators arrive with their own issues).
"""
