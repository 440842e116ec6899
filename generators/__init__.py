"""Built-in material generator plugins (import name `brdfbench_generators`).

Generators register in the `brdfbench.generators` entry-point group with a
`brdfbench.plugins.specs.GeneratorSpec` and implement `brdfbench.protocols.generator.Generator`:
`training_set` (the ceiling row), `pca_brdf` / `pca_nbrdf` (PCA-A / PCA-N), `vae_brdf` /
`vae_nbrdf` (VAE-A / VAE-N) and `hyperdiffusion`. Their samples are `samples.WeightSamples`
(NBRDF networks) or `samples.TableSamples` (MERL tables).
"""
