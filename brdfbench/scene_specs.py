"""The built-in scenes' plugin specs: light (no torch), so listing plugins imports nothing heavy."""

from __future__ import annotations

from .plugins.specs import SceneSpec

BRDF_SPACE = SceneSpec(
    name="brdf_space",
    description="No rendering: accuracy measured directly on BRDF values (MERL grid and random pairs)",
    target="brdfbench.scenes:brdf_space",
)
SPHERE_DIRECTIONAL = SceneSpec(
    name="sphere_directional",
    description="Unit sphere, two directional lights; closed form (one BRDF evaluation per pixel stratum and light), noise-free",
    target="brdfbench.scenes:sphere_directional",
)
SPHERE_ENVMAP = SceneSpec(
    name="sphere_envmap",
    description="Unit sphere under an HDR environment map (procedural sky or EXR); direct lighting with MIS",
    target="brdfbench.scenes:sphere_envmap",
)
SPHERES_ON_PLANE = SceneSpec(
    name="spheres_on_plane",
    description="Mitsuba XML: objects on a ground plane under sky and sun; occlusion and interreflection, path tracer",
    target="brdfbench.scenes:spheres_on_plane",
)
