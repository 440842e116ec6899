"""Entry-point specs of the built-in representations (light: imports no implementation)."""

from brdfbench.plugins.specs import RepresentationSpec

#: The kit's quick run of the literature's analytic models: a short fit.
QUICK_FIT = {"n_samples": 4096, "restarts": 1}

MERL = RepresentationSpec(
    name="merl",
    description="Tabulated MERL ground truth, 90x90x180 cells (nearest-cell as the reference reader, or trilinear)",
    target="brdfbench_representations.merl:TabulatedMERL",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "tabulated"}),
    reference={"mode": "nearest", "downsample": 1},
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
COOK_TORRANCE = RepresentationSpec(
    name="cook_torrance",
    description="Cook-Torrance as in Hu 2026: kd/pi + ks GGX(roughness^2) Schlick-GGX G (k = alpha^2/2) Schlick F(IoR); L1-log-cos fit",
    target="brdfbench_representations.analytic:CookTorrance",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
)
GGX = RepresentationSpec(
    name="ggx",
    description="Isotropic GGX microfacet: kd/pi + ks D(alpha) height-correlated Smith G2 Schlick F(F0); L1-log-cos fit",
    target="brdfbench_representations.analytic:GGX",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
)
BLINN_PHONG = RepresentationSpec(
    name="blinn_phong",
    description="Normalised Blinn-Phong: kd/pi + ks (n+8)/(8 pi) cos^n theta_h, exponent fitted in log space; L1-log-cos fit",
    target="brdfbench_representations.analytic:BlinnPhong",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
)
NBRDF = RepresentationSpec(
    name="nbrdf",
    description="Neural BRDF (Sztrajman et al. 2021): MLP 6-21-21-3 on Rusinkiewicz h, d; exp-1 output; batched L1-log-cos fit",
    target="brdfbench_representations.nbrdf:NBRDF",
    tags=frozenset({"isotropic", "fittable", "neural"}),
    kit_params={"epochs": 2, "n_samples": 100_000},  # the kit's quick run: a short fit
    network_features="rusinkiewicz",
)
NAIVE_MLP = RepresentationSpec(
    name="naive_mlp",
    description="The same MLP budget fed (wi, wo) directly: the naive neural baseline of Timonen et al.",
    target="brdfbench_representations.nbrdf:NaiveMLP",
    tags=frozenset({"fittable", "neural"}),
    kit_params={"epochs": 2, "n_samples": 100_000},  # the kit's quick run: a short fit
    network_features="directions",
)
TRIPLEPLANE = RepresentationSpec(
    name="tripleplane",
    description="Tripleplane (Xu et al. 2024, Timonen et al.'s baseline): radial h and polar d latent textures, SiLU MLP to log f",
    target="brdfbench_representations.triplane:Tripleplane",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "neural"}),
    kit_params={"epochs": 2, "n_samples": 60_000},  # the kit's quick run: a short fit
)
TRIPLANE_GATED = RepresentationSpec(
    name="triplane_gated",
    description="Triplane-gated (Timonen et al.): tripleplane with learned radial warps and latent-gated texels",
    target="brdfbench_representations.triplane:TriplaneGated",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "neural"}),
    kit_params={"epochs": 2, "n_samples": 60_000},  # the kit's quick run: a short fit
)
PUBLISHED_FIT = RepresentationSpec(
    name="published_fit",
    description="A published analytic fit of the target's MERL material (Ngan et al. 2005, Low et al. 2012, Bagher et al. 2012; via BBM), evaluated as published: no fitting",
    target="brdfbench_representations.published:PublishedFit",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params={"material": "alum-bronze"},  # the kit's synthetic material has no published fit
)
COOK_TORRANCE_BECKMANN = RepresentationSpec(
    name="cook_torrance_beckmann",
    description="Cook-Torrance as Ngan et al. 2005 fitted it: kd/pi + ks D_Beckmann(m) G_vgroove F_Schlick(F0) / (pi cos cos); L1-log-cos fit",
    target="brdfbench_representations.microfacet_models:CookTorranceBeckmann",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
COOK_TORRANCE_1982 = RepresentationSpec(
    name="cook_torrance_1982",
    description="Original Cook-Torrance (1982) as Low et al. 2012 fitted it: kd/pi + ks F(IoR) D_Beckmann(m) G_vgroove / (pi cos cos); L1-log-cos fit",
    target="brdfbench_representations.microfacet_models:CookTorrance1982",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
LOW_SMOOTH = RepresentationSpec(
    name="low_smooth",
    description="Low et al. 2012 smooth-surface (ABC) model: kd/pi + ks (1 + B Dp^2)^-C F(IoR); L1-log-cos fit",
    target="brdfbench_representations.microfacet_models:LowSmooth",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
LOW_MICROFACET = RepresentationSpec(
    name="low_microfacet",
    description="Low et al. 2012 microfacet model as in their published fits: kd/pi + ks (1 + B(1 - cos theta_h))^-C G_vgroove F(IoR) / (pi cos cos); L1-log-cos fit",
    target="brdfbench_representations.microfacet_models:LowMicrofacet",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
PHONG = RepresentationSpec(
    name="phong",
    description="Modified Phong (Lafortune and Willems 1994; Ngan et al.'s Blinn-Phong fits): kd/pi + ks (n+2)/(2 pi) cos^n(mirror angle); L1-log-cos fit",
    target="brdfbench_representations.ngan_models:Phong",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
WARD = RepresentationSpec(
    name="ward",
    description="Ward 1992 isotropic (as Ngan et al. 2005 fitted it): kd/pi + ks exp(-tan^2 theta_h/alpha^2)/(4 pi alpha^2 sqrt(cos_i cos_o)); L1-log-cos fit",
    target="brdfbench_representations.ngan_models:Ward",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
WARD_DUER = RepresentationSpec(
    name="ward_duer",
    description="Ward with Duer's 2006 normalisation: kd/pi + ks exp(-tan^2 theta_h/alpha^2)/(4 pi alpha^2 cos_i cos_o); L1-log-cos fit",
    target="brdfbench_representations.ngan_models:WardDuer",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
BLINN_PHONG_NGAN = RepresentationSpec(
    name="blinn_phong_ngan",
    description="Blinn's half-vector lobe kd/pi + ks (n+2)/(2 pi) cos^n theta_h, the normalisation of Ngan et al.'s Blinn-Phong fits; L1-log-cos fit",
    target="brdfbench_representations.ngan_models:BlinnPhongNgan",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
LAFORTUNE = RepresentationSpec(
    name="lafortune",
    description="One isotropic Lafortune et al. 1997 lobe with Ngan et al.'s normalisation (n+2)/(2 pi max(Cxy^2, Cz^2)^(n/2)); L1-log-cos fit",
    target="brdfbench_representations.ngan_models:Lafortune",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
LAFORTUNE2 = RepresentationSpec(
    name="lafortune2",
    description="Two isotropic Lafortune et al. 1997 lobes, each with Ngan et al.'s normalisation; L1-log-cos fit",
    target="brdfbench_representations.lafortune_lobes:Lafortune2",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
LAFORTUNE3 = RepresentationSpec(
    name="lafortune3",
    description="Three isotropic Lafortune et al. 1997 lobes, each with Ngan et al.'s normalisation; L1-log-cos fit",
    target="brdfbench_representations.lafortune_lobes:Lafortune3",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
ASHIKHMIN_SHIRLEY = RepresentationSpec(
    name="ashikhmin_shirley",
    description="Ashikhmin-Shirley 2000 specular term, isotropic, Schlick F(F0) (as Ngan et al. 2005 fitted it); L1-log-cos fit",
    target="brdfbench_representations.ngan_models:AshikhminShirley",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
ASHIKHMIN_SHIRLEY_IOR = RepresentationSpec(
    name="ashikhmin_shirley_ior",
    description="Ashikhmin-Shirley specular term with the dielectric Fresnel of an IoR (as Low et al. 2012 fitted it); L1-log-cos fit",
    target="brdfbench_representations.ngan_models:AshikhminShirleyIor",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
SGD = RepresentationSpec(
    name="sgd",
    description="Bagher et al. 2012 shifted gamma distribution microfacet (SGD): kd/pi + ks D_SGD(alpha, p; K_ap) G1 G1 F(F0, F1) / (pi cos cos), RGB shape; L1-log-cos fit",
    target="brdfbench_representations.sgd:SGD",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    kit_params=QUICK_FIT,  # the kit's quick run: a short fit
)
HE = RepresentationSpec(
    name="he",
    description="He et al. 1991 directional-diffuse term as Ngan et al. 2005 fitted it: kd/pi + ks F(IoR) G S(sigma0, tau) D / (pi cos cos), D the series over m at the RGB wavelengths (0.645, 0.526, 0.444 um); L1-log-cos fit",
    target="brdfbench_representations.he_model:He",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
    # the kit's quick run: a shorter fit than the other models' (each evaluation sums a series)
    kit_params={**QUICK_FIT, "n_samples": 1024},
)
