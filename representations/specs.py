"""Entry-point specs of the built-in representations (light: imports no implementation)."""

from brdfbench.specs import RepresentationSpec

MERL = RepresentationSpec(
    name="merl",
    description="Tabulated MERL ground truth, 90x90x180 cells (nearest-cell as the reference reader, or trilinear)",
    target="brdfbench_representations.merl:TabulatedMERL",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "tabulated"}),
)
LAMBERT = RepresentationSpec(
    name="lambert",
    description="Lambertian rho/pi, albedo fitted as the cosine-weighted median of the measured values",
    target="brdfbench_representations.lambert:Lambert",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
)
PCA = RepresentationSpec(
    name="pca",
    description="PCA of log-relative, cosine-weighted MERL tables (Nielsen et al. 2015); trained on a split, cross-validated",
    target="brdfbench_representations.pca:PCA",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "tabulated", "needs_training"}),
)
