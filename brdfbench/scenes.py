"""Scenes declare what they contain; the harness simulates only what that calls for.

This slice has the scene that needs no simulation at all: metrics computed directly in
BRDF space. Rendering scenes (directional lights, environment maps, path tracing) plug
into the same `brdfbench.scenes` group.
"""

from __future__ import annotations

from dataclasses import dataclass

from .specs import SceneSpec


@dataclass(frozen=True)
class Scene:
    name: str
    directional_lights: int = 0
    environment_map: str | None = None
    occluders: bool = False
    interreflection_depth: int = 0

    @property
    def needs_rendering(self) -> bool:
        return bool(self.directional_lights or self.environment_map or self.occluders or self.interreflection_depth)


def brdf_space() -> Scene:
    return Scene(name="brdf_space")


BRDF_SPACE = SceneSpec(
    name="brdf_space",
    description="No rendering: accuracy measured directly on BRDF values (MERL grid and random pairs)",
    target="brdfbench.scenes:brdf_space",
)
