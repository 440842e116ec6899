"""Entry-point specs of the built-in datasets."""

from ..plugins.specs import DatasetSpec

SYNTHETIC = DatasetSpec(
    name="synthetic",
    description="Embedded default: deterministic measured-like materials written as MERL .binary files to a cache",
    target="brdfbench.data.synthetic:synthetic_dataset",
)
MERL_FOLDER = DatasetSpec(
    name="merl_folder",
    description="Every MERL .binary file in a user-given folder",
    target="brdfbench.data.merl_folder:merl_folder_dataset",
)
NBRDF_RELEASE = DatasetSpec(
    name="nbrdf_release",
    description="Published NBRDF networks of real measured materials (Sztrajman et al. 2021) on the MERL grid",
    target="brdfbench.data.nbrdf_release:nbrdf_release_dataset",
    caveat=(
        "Targets are the published NBRDF networks (Sztrajman et al. 2021) evaluated on the MERL grid, "
        "not the measurements: refitting an NBRDF-generated table favours `nbrdf` (it can represent "
        "its target exactly), so its lead here overstates its accuracy on measured data."
    ),
)
AUGMERL = DatasetSpec(
    name="augmerl",
    description="AugMERL (Zhou et al.): a base set's RGB permutations (x6) and PCA-space interpolations of pairs, with a held-out test split",
    target="brdfbench.data.augmerl:augmerl_dataset",
    caveat=(
        "AugMERL materials are channel permutations and PCA-space interpolations of the base set's materials; "
        "test materials are held out at random, so a test material's parents or permutations may be in the "
        "training split (as in Zhou et al.)."
    ),
)
NEUMERL = DatasetSpec(
    name="neumerl",
    description="NeuMERL (Zhou et al.): AugMERL plus an aligned NBRDF weight vector per material (batched fits, init=shared, cached)",
    target="brdfbench.data.neumerl:neumerl_dataset",
    caveat=(
        "NeuMERL's tables are AugMERL's; its NBRDF weight vectors are fits to them (shared initialisation), "
        "so generators over weights can produce at best what a 6-21-21-3 NBRDF can represent."
    ),
)
