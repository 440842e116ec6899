"""Entry-point specs of the built-in samplers (light: imports no implementation)."""

from brdfbench.plugins.specs import SamplerSpec

_HEMISPHERE = frozenset({"hemisphere"})
_MICROFACET = frozenset({"microfacet"})

UNIFORM = SamplerSpec(
    name="uniform",
    description="Uniform hemisphere sampling, pdf 1/(2 pi), independent of wi",
    target="brdfbench.sampling.builtin:Uniform",
    tags=_HEMISPHERE,
)
COSINE = SamplerSpec(
    name="cosine",
    description="Cosine-weighted hemisphere sampling, pdf cos(theta)/pi, independent of wi",
    target="brdfbench.sampling.builtin:Cosine",
    tags=_HEMISPHERE,
)
POWER_COSINE = SamplerSpec(
    name="power_cosine",
    description="Power-cosine hemisphere sampling about the normal, pdf (n+1) cos^n(theta)/(2 pi)",
    target="brdfbench.sampling.builtin:PowerCosine",
    tags=_HEMISPHERE,
)
BLINN_PHONG = SamplerSpec(
    name="blinn_phong",
    description="Blinn-Phong half-vector sampling, D cos = (n+2) cos^(n+1)/(2 pi), reflected (pdf / 4|wo.h|)",
    target="brdfbench.sampling.builtin:BlinnPhong",
    tags=_MICROFACET,
)
BECKMANN = SamplerSpec(
    name="beckmann",
    description="Beckmann half-vector sampling (NDF with its 1/pi), reflected (pdf / 4|wo.h|)",
    target="brdfbench.sampling.builtin:Beckmann",
    tags=_MICROFACET,
)
GGX = SamplerSpec(
    name="ggx",
    description="GGX half-vector sampling from D(h) cos(theta_h), reflected (pdf / 4|wo.h|)",
    target="brdfbench.sampling.builtin:GGX",
    tags=_MICROFACET,
)
GGX_VNDF = SamplerSpec(
    name="ggx_vndf",
    description="GGX sampling of the normals visible from wi (Heitz 2018), reflected",
    target="brdfbench.sampling.builtin:GGXVisible",
    tags=_MICROFACET,
)
WARD = SamplerSpec(
    name="ward",
    description="Anisotropic Ward half-vector sampling (Ward 1992) with Walter's (2005) pdf "
    "exp(-tan^2(theta_h)(cos^2/ax^2 + sin^2/ay^2)) / (pi ax ay cos^3(theta_h)), reflected (pdf / 4|wo.h|)",
    target="brdfbench.sampling.lobes:Ward",
    tags=_MICROFACET,
)
ASHIKHMIN_SHIRLEY = SamplerSpec(
    name="ashikhmin_shirley",
    description="Ashikhmin-Shirley (2000) anisotropic half-vector sampling, "
    "p(h) = sqrt((nu+1)(nv+1))/(2 pi) cos^(nu cos^2 + nv sin^2)(theta_h), reflected (pdf / 4|wo.h|)",
    target="brdfbench.sampling.lobes:AshikhminShirley",
    tags=_MICROFACET,
)
PHONG = SamplerSpec(
    name="phong",
    description="Modified Phong lobe sampling (Lafortune & Willems 1994) about the mirror direction of wi, "
    "pdf (n+1) cos^n(alpha)/(2 pi); samples below the horizon have density 0",
    target="brdfbench.sampling.lobes:Phong",
)
LAFORTUNE = SamplerSpec(
    name="lafortune",
    description="One generalised cosine lobe (Lafortune et al. 1997) about normalise(cxy wi_x, cxy wi_y, cz wi_z), "
    "pdf (n+1) max(0, cos alpha)^n/(2 pi); samples below the horizon have density 0",
    target="brdfbench.sampling.lobes:Lafortune",
)
