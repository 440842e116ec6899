"""Entry-point specs of the built-in samplers (light: imports no implementation)."""

from brdfbench.specs import SamplerSpec

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
