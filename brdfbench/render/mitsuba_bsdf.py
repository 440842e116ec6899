"""One Mitsuba 3 BSDF adapter for every registered brdfbench representation.

`register_plugins()` registers, for the current Mitsuba variant, a BSDF plugin named after
each representation (`merl`, `ggx`, `nbrdf`, ..., third-party ones too); all are the same
adapter class. Mitsuba prefers its own plugins to registered ones, so a representation
named like one of them (`diffuse`, `measured`, ...) is registered as `brdfbench_<name>`
instead, with a warning (`plugin_name` says which). Properties:

- `filename`: a brdfbench `.safetensors` model file (`brdfbench.modelio`), or
- `model_id`: a handle to a live model, made by `bsdf_dict(model, rep_name=...)`;
- `sampler` (default "cosine"): an importance sampler (plugin group `samplers`), whose
  parameters are the remaining properties (e.g. `alpha`, `exponent`);
- `material`: the name error messages use (default: the file's stem, the object id, or
  the representation name);
- `kernel`: "auto" (default), "native" (fail unless both BRDF and sampler have drjit
  kernels) or "torch" (force the torch path, e.g. to cross-check a kernel).

The BSDF reflects on the front side only: a direction at or below the horizon gives 0.
Mitsuba's directions map onto the protocol's as physics has it: in radiance transport
`si.wi` points toward the viewer and `wo` toward the light, so the BRDF is
`model.eval(ωi=wo, ωo=si.wi)` (swapped in importance transport; the same for reciprocal
models). `eval` returns f·cosθ(wo); `pdf` and `sample` are the sampler's, drawing `wo`
given `si.wi`; `sample`'s weight is f·cosθ(wo)/pdf (0 where pdf is 0).

Two evaluation paths:

- native (drjit_kernels.py, drjit_samplers.py): drjit operations that Mitsuba traces into
  its symbolic kernels; per-material data are kernel inputs, so a second material of the
  same architecture reuses the compiled kernel;
- torch: the model's own `eval` (and the sampler's `sample`/`pdf`), taken by a model or
  sampler without a kernel, and always in scalar variants (slow: one sample a call). It
  needs concrete arrays, so Mitsuba must run in evaluated mode (symbolic loops and calls
  off): `needs_evaluated_mode(scene)` says whether it must (a symbolic call traces every
  live BSDF of the variant, so a torch-path BSDF of another scene still alive counts
  too), `render_mode(scene)` sets it, and `render(scene)` does both.

Mitsuba reports an error raised while constructing a plugin as a RuntimeError whose text
ends with the message; `load_dict` re-raises the adapter's own (ConfigError for a bad
property, ModelFileError for a missing or malformed model file).

Non-finite BRDF values are zeroed (the image stays finite) and counted per BSDF (a
`dr.scatter_reduce` into a counter, which works in symbolic mode); `check_finite(scene)`
raises `RenderError` naming the material and the representation.
"""

from __future__ import annotations

import contextlib
import warnings
import weakref
from pathlib import Path
from typing import Any, Iterable

import drjit as dr
import mitsuba as mi
import numpy as np
import torch

from .. import modelio
from ..plugins import registry
from ..errors import BrdfbenchError, ConfigError, ModelFileError, PluginError, RenderError
from ..protocols.representation import Representation
from .drjit_kernels import kernel_for
from .drjit_samplers import sampler_for
from .camera import Camera
from .mitsuba_integrators import DIRECT_MIS_INTEGRATOR, register_integrators

#: Properties the adapter reads itself; every other property is a sampler parameter.
RESERVED = ("filename", "model_id", "sampler", "material", "kernel")
KERNEL_MODES = ("auto", "native", "torch")
DEFAULT_SAMPLER = "cosine"

_MODELS: dict[str, tuple[str, Representation]] = {}  # model_id -> (representation name, model)
_CLASSES: dict[str, type] = {}  # Mitsuba variant -> adapter class
_REGISTERED: set[tuple[str, str]] = set()  # (variant, representation name)
_LIVE: "weakref.WeakSet[BrdfAdapter]" = weakref.WeakSet()  # adapters whose BSDF is alive


# --------------------------------------------------------------------------- drjit <-> torch


def _is_jit() -> bool:
    return dr.is_jit_v(mi.Float)


def _columns(*components) -> torch.Tensor:
    """Components (JIT arrays or scalars) as a float32 torch tensor (N, len(components))."""
    if not _is_jit():
        return torch.tensor([[float(c) for c in components]], dtype=torch.float32)
    dr.eval(*components)
    cols = [np.atleast_1d(np.asarray(c, dtype=np.float32)) for c in components]
    n = max(len(c) for c in cols)
    return torch.from_numpy(np.stack([np.broadcast_to(c, (n,)) for c in cols], axis=1).copy())


def _from_columns(t: torch.Tensor, cls):
    """A (N, k) torch tensor as the drjit type `cls` of k components; a (N,) one as mi.Float."""
    t = t.detach().to(torch.float32)
    if t.ndim == 1:
        return mi.Float(np.ascontiguousarray(t.numpy())) if _is_jit() else float(t[0])
    if _is_jit():
        return cls(*(mi.Float(np.ascontiguousarray(t[:, c].numpy())) for c in range(t.shape[1])))
    return cls(*(float(t[0, c]) for c in range(t.shape[1])))


def _lnot(mask):
    return ~mask if dr.is_array_v(mask) else not mask


# --------------------------------------------------------------------------- the adapter


class BrdfAdapter:
    """What one adapter BSDF evaluates: the model, its kernel or torch path, the sampler,
    and the non-finite counter. Works on drjit values; the Mitsuba class delegates here."""

    def __init__(self, model: Representation, rep_name: str, material: str, sampler: Any, sampler_name: str,
                 kernel: str = "auto"):
        self.model, self.rep_name, self.material = model, rep_name, material
        self.sampler, self.sampler_name = sampler, sampler_name
        self.kernel = None if kernel == "torch" else kernel_for(model)
        self.twin = None if kernel == "torch" else sampler_for(sampler)
        if kernel == "native" and (self.kernel is None or self.twin is None):
            missing = "representation" if self.kernel is None else "sampler"
            raise ConfigError(f"{self._where()}: kernel='native', but the {missing} has no drjit kernel here "
                              f"(variant {mi.variant()}); use kernel='auto'")
        self.counter = dr.zeros(mi.UInt32, 1) if _is_jit() else None
        self.host_count = 0
        self.variant = mi.variant()
        _LIVE.add(self)

    def _where(self) -> str:
        return f"BSDF {self.rep_name!r} (material {self.material!r})"

    # -- reporting ---------------------------------------------------------------
    @property
    def kernel_path(self) -> str:
        """"native" (a drjit kernel) or "torch" for the BRDF."""
        return "torch" if self.kernel is None else "native"

    @property
    def sampler_path(self) -> str:
        return "torch" if self.twin is None else "native"

    @property
    def uses_torch(self) -> bool:
        return _is_jit() and (self.kernel is None or self.twin is None)

    def nonfinite_count(self) -> int:
        jit = 0 if self.counter is None else int(np.asarray(self.counter)[0])
        return jit + self.host_count

    def reset_count(self) -> None:
        if self.counter is not None:
            self.counter = dr.zeros(mi.UInt32, 1)
        self.host_count = 0

    def describe(self) -> str:
        return (f"representation={self.rep_name!r}, material={self.material!r}, kernel={self.kernel_path}, "
                f"sampler={self.sampler_name!r} ({self.sampler_path})")

    # -- the BRDF ------------------------------------------------------------------
    def _torch_ready(self) -> None:
        if _is_jit() and dr.flag(dr.JitFlag.SymbolicScope):
            raise RenderError(f"{self._where()} evaluates in torch, which needs concrete values: render inside "
                              "brdfbench.render.mitsuba_bsdf.render_mode(scene) (or use mitsuba_bsdf.render)")

    def _count(self, bad) -> None:
        if self.counter is not None:
            dr.scatter_reduce(dr.ReduceOp.Add, self.counter, mi.UInt32(1), mi.UInt32(0), bad)
        elif bad:
            self.host_count += 1

    def brdf(self, light, view, active=True) -> mi.Color3f:
        """f(ωi = light, ωo = view), not cosine-weighted; 0 below the horizon and where
        non-finite (those lanes are counted)."""
        ok = active & (light.z > 0) & (view.z > 0)
        if self.kernel is not None:
            f = self.kernel.eval(light, view)
            if getattr(self.kernel, "finite", False):  # the kernel promises finite values
                return dr.select(ok, f, 0.0)
        else:
            self._torch_ready()
            with torch.no_grad():
                out = self.model.eval(_columns(light.x, light.y, light.z), _columns(view.x, view.y, view.z))
            f = _from_columns(out, mi.Color3f)
        finite = dr.isfinite(f.x) & dr.isfinite(f.y) & dr.isfinite(f.z)
        self._count(ok & _lnot(finite))
        return dr.select(ok & finite, f, 0.0)

    # -- the sampler ---------------------------------------------------------------
    def sample_direction(self, wi, u) -> mi.Vector3f:
        if self.twin is not None:
            return self.twin.sample(wi, u)
        self._torch_ready()
        with torch.no_grad():
            wo = self.sampler.sample(_columns(wi.x, wi.y, wi.z), _columns(u.x, u.y))
        return _from_columns(wo, mi.Vector3f)

    def density(self, wi, wo, active=True) -> mi.Float:
        if self.twin is not None:
            p = self.twin.pdf(wi, wo)
        else:
            self._torch_ready()
            with torch.no_grad():
                p = _from_columns(self.sampler.pdf(_columns(wi.x, wi.y, wi.z), _columns(wo.x, wo.y, wo.z)), None)
        return dr.select(active & dr.isfinite(p) & (p > 0), p, 0.0)

    # -- Mitsuba's BSDF interface --------------------------------------------------
    @staticmethod
    def _enabled(ctx) -> bool:
        return ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)

    @staticmethod
    def _light_view(ctx, wi, wo):
        """(toward the light, toward the viewer) for Mitsuba's (si.wi, wo)."""
        return (wi, wo) if ctx.mode == mi.TransportMode.Importance else (wo, wi)

    def eval(self, ctx, si, wo, active=True):
        if not self._enabled(ctx):
            return mi.Color3f(0.0)
        light, view = self._light_view(ctx, si.wi, wo)
        return self.brdf(light, view, active) * wo.z

    def pdf(self, ctx, si, wo, active=True):
        if not self._enabled(ctx):
            return mi.Float(0.0)
        return self.density(si.wi, wo, active)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        bs = dr.zeros(mi.BSDFSample3f)
        if not self._enabled(ctx):
            return bs, mi.Color3f(0.0)
        wo = self.sample_direction(si.wi, sample2)
        pdf = self.density(si.wi, wo, active)
        light, view = self._light_view(ctx, si.wi, wo)
        f = self.brdf(light, view, active)
        ok = pdf > 0
        bs.wo, bs.pdf, bs.eta = wo, pdf, 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        return bs, dr.select(ok, f * wo.z / dr.select(ok, pdf, 1.0), 0.0)


# --------------------------------------------------------------------------- properties


def _load_model(props, rep_name: str) -> tuple[Representation, str]:
    """The model named by `filename` or `model_id`, and a default material name."""
    has_file, has_id = "filename" in props, "model_id" in props
    if has_file == has_id:
        got = "both" if has_file else "neither"
        raise ConfigError(f"BSDF {rep_name!r}: give exactly one of 'filename' (a brdfbench .safetensors model) "
                          f"or 'model_id' (from mitsuba_bsdf.bsdf_dict); got {got}")
    if has_id:
        handle = str(props["model_id"])
        if handle not in _MODELS:
            raise ConfigError(f"BSDF {rep_name!r}: model_id={handle!r} is unknown in this process "
                              "(make it with brdfbench.render.mitsuba_bsdf.bsdf_dict)")
        name, model = _MODELS[handle]
        source = f"model_id={handle!r}"
        default = ""
    else:
        raw = str(props["filename"])
        path = Path(str(mi.file_resolver().resolve(raw)))
        if not path.is_file():
            raise ModelFileError(f"BSDF {rep_name!r}: filename={raw!r}: no such model file")
        name, model = modelio.load(path)
        source = f"model file {path}"
        default = path.stem
    if name != rep_name:
        raise ConfigError(f"BSDF {rep_name!r}: {source} holds a {name!r} model; use type={plugin_name(name)!r}")
    return model, default


def _make_sampler(name: str, params: dict[str, Any], where: str):
    try:
        spec = registry.get("samplers", name)
    except PluginError as exc:
        raise ConfigError(f"{where}: sampler={name!r}: {exc}") from None
    try:
        return spec.create(**params)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    except TypeError:
        keys = ", ".join(repr(k) for k in params) or "none"
        raise ConfigError(f"{where}: sampler {name!r} does not take the parameter(s) {keys}; properties other than "
                          f"{', '.join(RESERVED)} are sampler parameters") from None


def adapter_from_props(props, rep_name: str) -> BrdfAdapter:
    """Parse and check an adapter's Mitsuba properties (see the module docstring)."""
    model, default = _load_model(props, rep_name)
    material = str(props["material"]) if "material" in props else (default or props.id() or rep_name)
    where = f"BSDF {rep_name!r} (material {material!r})"
    sampler_name = str(props["sampler"]) if "sampler" in props else DEFAULT_SAMPLER
    kernel = str(props["kernel"]) if "kernel" in props else "auto"
    if kernel not in KERNEL_MODES:
        raise ConfigError(f"{where}: kernel={kernel!r}; expected one of {', '.join(KERNEL_MODES)}")
    params = {k: props[k] for k in props.keys() if k not in RESERVED}
    sampler = _make_sampler(sampler_name, params, where)
    return BrdfAdapter(model, rep_name, material, sampler, sampler_name, kernel)


# --------------------------------------------------------------------------- the Mitsuba class


def _define_class(base: type) -> type:
    """The adapter as a subclass of the current variant's mi.BSDF (one class per variant)."""

    class BrdfbenchBSDF(base):
        """A brdfbench representation as a front-side reflection BSDF (see mitsuba_bsdf.py)."""

        def __init__(self, props, rep_name: str):
            base.__init__(self, props)
            self.adapter = adapter_from_props(props, rep_name)
            flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            self.m_flags = flags
            self.m_components = [flags]

        def eval(self, ctx, si, wo, active=True):
            return self.adapter.eval(ctx, si, wo, active)

        def pdf(self, ctx, si, wo, active=True):
            return self.adapter.pdf(ctx, si, wo, active)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.adapter.eval_pdf(ctx, si, wo, active)

        def sample(self, ctx, si, sample1, sample2, active=True):
            return self.adapter.sample(ctx, si, sample1, sample2, active)

        def traverse(self, callback):
            # Exposed so that mi.traverse finds adapters nested in other BSDFs (see adapters_in).
            if self.adapter.counter is not None:
                callback.put("nonfinite_count", self.adapter.counter, mi.ParamFlags.NonDifferentiable)

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return f"BrdfbenchBSDF[{self.adapter.describe()}]"

    return BrdfbenchBSDF


def _current_variant() -> str:
    variant = mi.variant()
    if variant is None:
        raise ConfigError("no Mitsuba variant is set; set one first (brdfbench.mitsuba_env.mitsuba_variant)")
    return variant


def adapter_class() -> type:
    """The adapter's mi.BSDF subclass for the current variant."""
    variant = _current_variant()
    if variant not in _CLASSES:
        _CLASSES[variant] = _define_class(mi.BSDF)
    return _CLASSES[variant]


PLUGIN_PREFIX = "brdfbench_"
#: The plugin of a live model whose class is no registered representation (the render
#: harness's table reference): reached through `model_id` only.
UNREGISTERED = PLUGIN_PREFIX + "model"


def plugin_name(rep_name: str) -> str:
    """The Mitsuba plugin name of a representation: its own name, or `brdfbench_<name>`
    where Mitsuba has a plugin of that name (which would shadow a registered one)."""
    _current_variant()
    builtin = mi.PluginManager.instance().plugin_type(rep_name) != mi.ObjectType.Unknown
    return PLUGIN_PREFIX + rep_name if builtin else rep_name


def register_plugins() -> list[str]:
    """Register one BSDF plugin per registered representation for the current variant
    (idempotent; call again after registering more representations). Returns the
    representation names (see `plugin_name` for the plugins')."""
    cls = adapter_class()
    variant = mi.variant()
    names = registry.names("representations")
    for name in names:
        if (variant, name) not in _REGISTERED:
            plugin = plugin_name(name)
            if plugin != name:
                warnings.warn(f"representation {name!r} is named like Mitsuba's own plugin {name!r}, which would "
                              f"shadow it: its BSDF is registered as {plugin!r}", stacklevel=2)
            mi.register_bsdf(plugin, lambda props, name=name: _construct(cls, props, name))
            _REGISTERED.add((variant, name))
    if (variant, UNREGISTERED) not in _REGISTERED:
        mi.register_bsdf(UNREGISTERED, lambda props: _construct(cls, props, UNREGISTERED))
        _REGISTERED.add((variant, UNREGISTERED))
    return names


_last_error: list[BrdfbenchError] = []


def _construct(cls: type, props, rep_name: str):
    """Make an adapter; remember a property error, which Mitsuba wraps in a RuntimeError."""
    try:
        return cls(props, rep_name)
    except BrdfbenchError as exc:
        _last_error[:] = [exc]
        raise


def load_dict(d: dict):
    """mi.load_dict, re-raising an adapter's property error as the brdfbench error it is
    (Mitsuba reports it as a RuntimeError with a traceback)."""
    _last_error.clear()
    try:
        return mi.load_dict(d)
    except RuntimeError as exc:
        if _last_error and str(_last_error[0]) in str(exc):
            raise _last_error[0] from None
        raise
    finally:
        _last_error.clear()


def bsdf_dict(model: Representation, *, rep_name: str, sampler: str = DEFAULT_SAMPLER,
              sampler_params: dict[str, Any] | None = None, material: str = "", kernel: str = "auto") -> dict:
    """A BSDF dict for `mi.load_dict` rendering a live model; the model is kept in a module
    table under its `model_id` (until `forget_models()`). Registers the plugins if a
    variant is set."""
    handle = f"{rep_name}@{id(model):x}"
    _MODELS[handle] = (rep_name, model)
    kind = plugin_name(rep_name) if mi.variant() is not None else rep_name
    out: dict[str, Any] = {"type": kind, "model_id": handle, "sampler": sampler, "material": material or rep_name}
    if kernel != "auto":
        out["kernel"] = kernel
    for key, value in (sampler_params or {}).items():
        if key in RESERVED or key in ("type", "id"):
            raise ConfigError(f"sampler parameter {key!r} clashes with an adapter property ({', '.join(RESERVED)})")
        out[key] = value
    if mi.variant() is not None:
        register_plugins()
    return out


def forget_models() -> None:
    """Drop every model `bsdf_dict` kept alive (BSDFs already loaded keep theirs)."""
    _MODELS.clear()


# --------------------------------------------------------------------------- scenes


def adapters_in(scene_or_bsdfs) -> list[BrdfAdapter]:
    """The adapters of a scene (its shapes' BSDFs, and any nested one mi.traverse finds),
    of a BSDF, or of an iterable of BSDFs."""
    if isinstance(scene_or_bsdfs, mi.Scene):
        objects = [shape.bsdf() for shape in scene_or_bsdfs.shapes()]
        params = mi.traverse(scene_or_bsdfs)
        objects += [params.properties[key][2] for key in params.keys()]
    elif isinstance(scene_or_bsdfs, Iterable):
        objects = list(scene_or_bsdfs)
    else:
        objects = [scene_or_bsdfs]
    found: dict[int, BrdfAdapter] = {}
    for obj in objects:
        adapter = getattr(obj, "adapter", None)
        if isinstance(adapter, BrdfAdapter):
            found[id(adapter)] = adapter
    return list(found.values())


def needs_evaluated_mode(scene_or_bsdfs=None) -> bool:
    """Whether Mitsuba must render in evaluated mode: an adapter of the scene (or of the
    given BSDFs) evaluates in torch, or any live one of this variant does, since a
    symbolic call traces every BSDF instance, used by the scene or not."""
    variant = mi.variant()
    live = [a for a in list(_LIVE) if a.variant == variant]
    scene = [] if scene_or_bsdfs is None else adapters_in(scene_or_bsdfs)
    return any(a.uses_torch for a in live + scene)


@contextlib.contextmanager
def render_mode(scene_or_bsdfs):
    """Turn symbolic loops and calls off for the block where a torch-path adapter needs it;
    yields whether it did."""
    if not needs_evaluated_mode(scene_or_bsdfs):
        yield False
        return
    with dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, False), dr.scoped_set_flag(dr.JitFlag.SymbolicCalls, False):
        yield True


def check_finite(scene_or_bsdfs, *, reset: bool = True) -> None:
    """Raise RenderError if an adapter met non-finite BRDF values since the last check
    (they were rendered as 0); with `reset`, start counting afresh."""
    adapters = adapters_in(scene_or_bsdfs)
    faults = [(a, a.nonfinite_count()) for a in adapters]
    if reset:
        for a in adapters:
            a.reset_count()
    faults = [(a, n) for a, n in faults if n > 0]
    if faults:
        parts = "; ".join(f"material {a.material!r} (representation {a.rep_name!r}): {n} non-finite BRDF value(s)"
                          for a, n in faults)
        raise RenderError(f"render produced non-finite values, rendered as 0: {parts}")


def render(scene, *, seed: int = 0, spp: int = 0, check: bool = True):
    """mi.render in the mode the scene's adapters need, then `check_finite`."""
    with render_mode(scene):
        image = mi.render(scene, seed=seed, spp=spp)
        dr.eval(image)
    if check:
        check_finite(scene)
    return image


def sphere_scene(bsdf: dict, *, resolution: int = 256, spp: int = 16, max_depth: int = 2, seed: int = 0,
                 light_direction=(-1.0, -1.0, -1.0), irradiance: float = 3.0, ambient: float = 0.1,
                 integrator: str = "path") -> dict:
    """A scene dict: the unit sphere with `bsdf` filling a square perspective view (box
    filter), lit by one directional light and a constant ambient, rendered by Mitsuba's
    `path` integrator (with `max_depth`), or with integrator="direct_mis" by brdfbench's
    direct-lighting integrator for convex objects (which calls the BSDF without dispatch)."""
    if integrator == "direct_mis":
        register_integrators()
        integrator_dict: dict[str, Any] = {"type": DIRECT_MIS_INTEGRATOR}
    elif integrator == "path":
        integrator_dict = {"type": "path", "max_depth": max_depth}
    else:
        raise ConfigError(f"sphere_scene: integrator={integrator!r}; expected 'path' or 'direct_mis'")
    return {
        "type": "scene",
        "integrator": integrator_dict,
        "sensor": Camera(width=resolution, height=resolution).mitsuba_dict(spp, seed),
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "sun": {"type": "directional", "direction": list(light_direction),
                "irradiance": {"type": "rgb", "value": irradiance}},
        "ambient": {"type": "constant", "radiance": {"type": "rgb", "value": ambient}},
    }
