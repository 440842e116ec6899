"""Entry-point specs of the built-in datasets."""

from ..specs import DatasetSpec

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
