"""Scenes declare what they contain; the harness simulates only what that calls for.

A scene lists its effects: directional lights, an environment map, its geometry (none, the
unit sphere, or a Mitsuba XML scene), whether anything occludes the object, and how many
bounces of light it needs (`max_depth`, Mitsuba's meaning: 2 = direct lighting only).
`simulator_for` picks the cheapest simulator that is exact for those effects:

| effects                                              | simulator     | noise        |
|------------------------------------------------------|---------------|--------------|
| none (BRDF-space metrics)                            | `brdf_space`  | none         |
| convex object, directional lights only               | `closed_form` | none         |
| convex object, environment map (+ directional)       | `direct_mis`  | Monte Carlo  |
| occlusion or interreflection (any XML scene)         | `path`        | Monte Carlo  |

A convex object never sees itself, so for it direct lighting is all the light there is,
whatever `max_depth` says. Scene factories are plugins (group `brdfbench.scenes`) called
with the `scene.params` of the Hydra config.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from .errors import ConfigError
from .render.camera import Camera

SIMULATORS = ("brdf_space", "closed_form", "direct_mis", "path")
GEOMETRIES = ("none", "sphere", "xml")
PROCEDURAL_SKY = "procedural"
XML_DIR = Path(__file__).resolve().parent / "scenes_xml"


@dataclass(frozen=True)
class DirectionalLight:
    """A light at infinity; `direction` is where its light travels (Mitsuba's convention)."""

    direction: tuple[float, float, float]
    irradiance: tuple[float, float, float]  # W/m² on a surface facing the light, per RGB channel


@dataclass(frozen=True)
class Environment:
    """An HDR lat-long environment: the procedural sky, or a user's EXR file."""

    source: str = PROCEDURAL_SKY
    scale: float = 1.0


@dataclass(frozen=True)
class Scene:
    name: str
    geometry: str = "none"
    camera: Camera | None = None
    lights: tuple[DirectionalLight, ...] = ()
    environment: Environment | None = None
    xml: Path | None = None
    occlusion: bool = False
    max_depth: int = 2
    spp: int = 64  # samples per pixel for Monte Carlo simulators
    supersample: int = 1  # per-axis strata per pixel for the closed form (1: the pixel centre)
    params: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def needs_rendering(self) -> bool:
        return self.geometry != "none"

    @property
    def convex(self) -> bool:
        return self.geometry == "sphere" and not self.occlusion

    def simulator(self) -> str:
        """The cheapest simulator exact for this scene's effects (see the module table)."""
        if not self.needs_rendering:
            return "brdf_space"
        if self.convex and self.environment is None:
            return "closed_form"
        if self.convex:
            return "direct_mis"
        return "path"

    def allowed_simulators(self) -> tuple[str, ...]:
        """Simulators exact for this scene: the cheap one, and the path tracer for any rendered scene."""
        if not self.needs_rendering:
            return ("brdf_space",)
        if self.geometry == "xml":
            return ("path",)
        cheap = self.simulator()
        return (cheap, "path") if cheap != "path" else ("path",)

    def chosen_simulator(self, name: str | None = None) -> str:
        """`name` (harness.simulator), or the cheapest exact one when None; a ConfigError
        naming the key when that simulator is not exact for this scene."""
        chosen = name or self.simulator()
        if chosen not in self.allowed_simulators():
            raise ConfigError(f"harness.simulator={chosen!r} cannot render scene {self.name!r} exactly; "
                              f"it allows {', '.join(self.allowed_simulators())}")
        return chosen


# --------------------------------------------------------------------------- parameters


def _vec3(value: Any, key: str) -> tuple[float, float, float]:
    try:
        vec = tuple(float(v) for v in (value if isinstance(value, (list, tuple)) else [value] * 3))
    except (TypeError, ValueError):
        raise ConfigError(f"scene.params.{key}={value!r} must be a number or a list of 3 numbers") from None
    if len(vec) != 3 or not all(math.isfinite(v) for v in vec):
        raise ConfigError(f"scene.params.{key}={value!r} must be a number or a list of 3 finite numbers")
    return vec  # type: ignore[return-value]


def _positive_int(value: Any, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"scene.params.{key}={value!r} must be a positive integer")
    return value


def _camera(width: int, height: int, fov: float, distance: float) -> Camera:
    _positive_int(width, "width"), _positive_int(height, "height")
    if not 0 < float(fov) < 180:
        raise ConfigError(f"scene.params.fov={fov!r} must be in (0, 180) degrees")
    if not float(distance) > 1:
        raise ConfigError(f"scene.params.distance={distance!r} must exceed the sphere's radius 1")
    return Camera(width=width, height=height, fov=float(fov), origin=(0.0, 0.0, float(distance)))


def _lights(specs: Sequence[dict] | None) -> tuple[DirectionalLight, ...]:
    out = []
    for i, spec in enumerate(specs or ()):
        if not isinstance(spec, dict) or set(spec) - {"direction", "irradiance"} or "direction" not in spec:
            raise ConfigError(f"scene.params.lights[{i}]={spec!r} must be a mapping with 'direction' and optional 'irradiance'")
        direction = _vec3(spec["direction"], f"lights[{i}].direction")
        if math.hypot(*direction) == 0:
            raise ConfigError(f"scene.params.lights[{i}].direction must not be zero")
        irradiance = _vec3(spec.get("irradiance", 1.0), f"lights[{i}].irradiance")
        if min(irradiance) < 0:
            raise ConfigError(f"scene.params.lights[{i}].irradiance={irradiance} must be non-negative")
        out.append(DirectionalLight(direction, irradiance))
    return tuple(out)


#: A key light from the upper right behind the camera, and a rim light from behind that
#: shows grazing angles (where Fresnel and shadowing terms differ most between models).
DEFAULT_LIGHTS = (
    {"direction": [-1.0, -1.0, -1.0], "irradiance": 3.0},
    {"direction": [0.6, -0.2, 1.0], "irradiance": 1.5},
)


# --------------------------------------------------------------------------- scene factories


def brdf_space() -> Scene:
    return Scene(name="brdf_space")


def sphere_directional(width: int = 256, height: int = 256, fov: float = 30.0, distance: float = 4.0,
                       lights: Sequence[dict] | None = None, supersample: int = 1) -> Scene:
    """The unit sphere under directional lights: the closed form, noise-free."""
    return Scene(
        name="sphere_directional", geometry="sphere", camera=_camera(width, height, fov, distance),
        lights=_lights(DEFAULT_LIGHTS if lights is None else lights),
        supersample=_positive_int(supersample, "supersample"),
    )


def sphere_envmap(width: int = 256, height: int = 256, fov: float = 30.0, distance: float = 4.0,
                  envmap: str = PROCEDURAL_SKY, envmap_scale: float = 1.0, lights: Sequence[dict] | None = None,
                  spp: int = 64) -> Scene:
    """The unit sphere under an HDR environment (the procedural sky or a user EXR): direct MIS."""
    if envmap != PROCEDURAL_SKY and not Path(envmap).is_file():
        raise ConfigError(f"scene.params.envmap={envmap!r}: no such file (use {PROCEDURAL_SKY!r} or a lat-long .exr)")
    if not float(envmap_scale) > 0:
        raise ConfigError(f"scene.params.envmap_scale={envmap_scale!r} must be positive")
    return Scene(
        name="sphere_envmap", geometry="sphere", camera=_camera(width, height, fov, distance),
        lights=_lights(lights), environment=Environment(envmap, float(envmap_scale)), spp=_positive_int(spp, "spp"),
    )


def spheres_on_plane(xml: str | None = None, width: int = 256, height: int = 192, spp: int = 64, max_depth: int = 4) -> Scene:
    """Several objects on a ground plane under a sky and a sun (a Mitsuba XML scene): path tracing.

    Any Mitsuba XML scene can stand in (`xml`), if it declares the material under test as
    `<bsdf type="$bsdf" id="material"> <string name="model_id" value="$model_id"/> …`
    (see brdfbench/scenes_xml/spheres_on_plane.xml)."""
    path = Path(xml) if xml else XML_DIR / "spheres_on_plane.xml"
    if not path.is_file():
        raise ConfigError(f"scene.params.xml={str(path)!r}: no such file")
    return Scene(
        name="spheres_on_plane", geometry="xml", xml=path, camera=Camera(width=_positive_int(width, "width"),
                                                                          height=_positive_int(height, "height")),
        occlusion=True, max_depth=_positive_int(max_depth, "max_depth"), spp=_positive_int(spp, "spp"),
    )
