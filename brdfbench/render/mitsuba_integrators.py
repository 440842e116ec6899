"""brdfbench's own Mitsuba 3 integrators: closed form and direct MIS, for convex objects.

- `brdfbench_closed_form`: at each camera hit, f·cosθ·E summed over the directional
  lights (`emitter.sample_direction` of a delta light is deterministic); nothing else is
  traced, which is exact for a convex object, since it cannot shadow itself;
- `brdfbench_direct_mis`: one environment sample and one BSDF sample per camera sample,
  weighted by the power heuristic, plus the closed-form term of each directional light.
  A convex object sees only the lights, so it traces no shadow ray and no second ray (a
  direction above the surface escapes to the environment).

Both call the scene's BSDF directly when the scene has one shape (`scene_bsdf`). Used by
the Mitsuba simulators (mitsuba_sim.py) and the adapter's `sphere_scene` (mitsuba_bsdf.py);
this module imports neither. Mitsuba is imported on first use.
"""

from __future__ import annotations

CLOSED_FORM_INTEGRATOR = "brdfbench_closed_form"
DIRECT_MIS_INTEGRATOR = "brdfbench_direct_mis"


def register_integrators() -> None:
    """Register the closed-form and direct-MIS integrators for the current variant (idempotent)."""
    import mitsuba as mi

    variant = mi.variant()
    if variant in _REGISTERED_VARIANTS:
        return
    closed_form, direct_mis = _integrator_classes()
    mi.register_integrator(CLOSED_FORM_INTEGRATOR, lambda props: closed_form(props))
    mi.register_integrator(DIRECT_MIS_INTEGRATOR, lambda props: direct_mis(props))
    _REGISTERED_VARIANTS.add(variant)


_REGISTERED_VARIANTS: set[str] = set()


def scene_bsdf(scene, si, ray):
    """The BSDF to shade `si` with: the only shape's own BSDF object when the scene has one
    shape (a direct call, traced inline), else the per-lane BSDF pointer (a virtual call)."""
    shapes = scene.shapes()
    if len(shapes) == 1 and shapes[0].bsdf() is not None:
        return shapes[0].bsdf()
    return si.bsdf(ray)


def power_heuristic(a, b):
    """a² / (a² + b²), 0 where undefined (both densities 0 or infinite)."""
    import drjit as dr

    a2, b2 = a * a, b * b
    w = a2 / (a2 + b2)
    return dr.select(dr.isfinite(w), w, 0.0)


def _integrator_classes():
    import drjit as dr
    import mitsuba as mi

    def delta_lights(scene, si, bsdf, ctx, valid):
        """Σ over directional (delta) lights of f·cosθ·E at `si`; no shadow rays."""
        radiance = mi.Color3f(0.0)
        for emitter in scene.emitters():
            if emitter.is_environment():
                continue
            ds, irradiance = emitter.sample_direction(si, mi.Point2f(0.5, 0.5), valid)
            radiance += bsdf.eval(ctx, si, si.to_local(ds.d), valid) * irradiance
        return radiance

    class ClosedFormIntegrator(mi.SamplingIntegrator):
        """Σ over delta lights of f·cosθ·E at the camera hit; no shadow rays, no bounces."""

        def sample(self, scene, sampler, ray, medium=None, active=True):
            si = scene.ray_intersect(ray, active)
            valid = active & si.is_valid()
            radiance = delta_lights(scene, si, scene_bsdf(scene, si, ray), mi.BSDFContext(), valid)
            return dr.select(valid, radiance, 0.0), valid, []

        def to_string(self):
            return "BrdfbenchClosedForm[]"

    class DirectMISIntegrator(mi.SamplingIntegrator):
        """Direct lighting of a convex object: one environment sample and one BSDF sample
        combined by the power heuristic, plus each directional light in closed form."""

        def sample(self, scene, sampler, ray, medium=None, active=True):
            si = scene.ray_intersect(ray, active)
            valid = active & si.is_valid()
            bsdf = scene_bsdf(scene, si, ray)
            ctx = mi.BSDFContext()
            u_env, u_lobe, u_bsdf = sampler.next_2d(valid), sampler.next_1d(valid), sampler.next_2d(valid)
            radiance = delta_lights(scene, si, bsdf, ctx, valid)
            env = scene.environment()
            if env is None:
                return dr.select(valid, radiance, 0.0), valid, []
            # the environment sample
            ds, env_weight = env.sample_direction(si, u_env, valid)  # weight = radiance / pdf
            ok = valid & (ds.pdf > 0)
            f, bsdf_pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), ok)
            radiance += dr.select(ok, f * env_weight * power_heuristic(ds.pdf, bsdf_pdf), 0.0)
            # the BSDF sample: above the surface it escapes to the environment
            bs, bsdf_weight = bsdf.sample(ctx, si, u_lobe, u_bsdf, valid)  # weight = f cosθ / pdf
            ok = valid & (bs.pdf > 0)
            seen = dr.zeros(mi.SurfaceInteraction3f)
            seen.t, seen.p, seen.wi = dr.inf, si.p, -si.to_world(bs.wo)
            env_pdf = env.pdf_direction(si, mi.DirectionSample3f(scene, seen, si), ok)
            radiance += dr.select(ok, bsdf_weight * env.eval(seen, ok) * power_heuristic(bs.pdf, env_pdf), 0.0)
            return dr.select(valid, radiance, 0.0), valid, []

        def to_string(self):
            return "BrdfbenchDirectMIS[]"

    return ClosedFormIntegrator, DirectMISIntegrator
