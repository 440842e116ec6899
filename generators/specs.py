"""Entry-point specs of the built-in generators (light: imports no implementation)."""

from brdfbench.plugins.specs import GeneratorSpec

TRAINING_SET = GeneratorSpec(
    name="training_set",
    description="The training split itself, sampled without replacement: the ceiling row of Zhou et al.'s Table 1",
    target="brdfbench_generators.training_set:TrainingSet",
    learns_from="tables",
    xfail_checks={"save_load_roundtrip": "it holds its training materials' names, not their tables: "
                                         "a loaded one samples only once attach()ed to the data"},
)
PCA_BRDF = GeneratorSpec(
    name="pca_brdf",
    description="PCA-A (Zhou et al.): PCA of log-relative, cosine-weighted MERL tables (k = 300, capped at n - 1), "
                "Gaussian in the principal space",
    target="brdfbench_generators.pca:PCABRDF",
    learns_from="tables",
)
PCA_NBRDF = GeneratorSpec(
    name="pca_nbrdf",
    description="PCA-N (Zhou et al.): PCA of aligned NBRDF weight vectors (k = 100, capped at N - 1), "
                "Gaussian in the principal space",
    target="brdfbench_generators.pca:PCANBRDF",
    learns_from="nbrdf",
)
VAE_BRDF = GeneratorSpec(
    name="vae_brdf",
    description="VAE-A (Zhou et al.): MLP VAE (latent 300) over MERL tables downsampled to 45x45x90 through a fixed "
                "PCA reduction of the training tables, nearest upsampling",
    target="brdfbench_generators.vae:VAEBRDF",
    learns_from="tables",
    kit_params={"epochs": 2},
)
VAE_NBRDF = GeneratorSpec(
    name="vae_nbrdf",
    description="VAE-N (Zhou et al.): MLP encoder/decoder over aligned NBRDF weight vectors, latent 100",
    target="brdfbench_generators.vae:VAENBRDF",
    learns_from="nbrdf",
    kit_params={"epochs": 20},
)
HYPERDIFFUSION = GeneratorSpec(
    name="hyperdiffusion",
    description="Transformer denoiser over NBRDF weight vectors: DDPM training (T = 100, linear beta), DDIM sampling, CFG hook",
    target="brdfbench_generators.hyperdiffusion:HyperDiffusion",
    learns_from="nbrdf",
    tags=frozenset({"conditional"}),
    kit_params={"epochs": 5},
)

# The generation harness lives beside the generators, registered as any harness plugin.
from brdfbench.plugins.specs import HarnessSpec  # noqa: E402

GENERATION = HarnessSpec(
    name="generation",
    description="Generators: sample draws scored against a held-out test set (MMD / COV / 1-NNA per distance, FID, categories)",
    target="brdfbench_generators.harness:GenerationHarness",
)
