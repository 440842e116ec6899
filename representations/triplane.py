"""`tripleplane` (Xu et al. 2024; the baseline of Timonen et al.): latent textures over the half and
difference vectors decoded by a small SiLU MLP to log f (the arithmetic: triplane_model.py;
the batched fit: triplane_fit.py).

Isotropic and reciprocal by construction (the half texture is radial; the difference
texture is read with φd mod π). Fitted `batch_materials` materials at a time; a material's
initial state is drawn from the run seed and its name, so its fit does not depend on its
batch-mates.

Both models run on the CPU or a CUDA device (`to(device)`): they fit there, the fitted
models live there, and `eval` takes inputs there. A recipe too long for a CPU (the
published one of Timonen et al.: 100k steps of 2^18 pairs) is refused when a fit would
start on the CPU, with its estimated time, unless `allow_slow_cpu` is set.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Sequence

import torch

from brdfbench import reused
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.protocols.representation import FIT_LOSS_KEY, Material, Representation

from . import triplane_fit as tf
from . import triplane_model as tm
from .nbrdf import material_seed

DEFAULTS = {"h_res": 64, "d_res": (32, 32), "channels": (8, 8), "hidden": (16,)}
#: A texture larger than this many floats per material is refused before allocation.
MAX_TEXTURE_FLOATS = 64 * 2**20
#: The training arithmetic assumed of a CPU in this fitter, for the estimate behind the
#: refusal below (an order of magnitude: texture gathers and 16-wide matrices run far below
#: a CPU's peak).
CPU_TRAIN_FLOP_RATE = 1e9
#: A fit estimated to take longer than this per material on the CPU is refused unless
#: `allow_slow_cpu` is set (the default recipe is estimated at under a minute).
CPU_LIMIT_S = 3600.0
#: On a GPU, materials fitted together at least (while a step holds at most
#: GPU_PAIRS_PER_STEP material-pairs): at the default minibatch a step is small kernels
#: whose launches, not their work, set its time (as for nbrdf), and a fit does not depend on
#: its batch-mates, so only speed changes. At the published recipe's 2^18 pairs: 16.
GPU_BATCH_MATERIALS = 128
GPU_PAIRS_PER_STEP = 2**22

_RECIPE_KEYS = ("epochs", "batch_size", "n_samples", "lr", "texture_lr", "loss", "beta1", "ema", "precondition",
                "init_scale", "iterations", "resample", "sampling", "schedule", "lr_decay", "lr_decay_every")


def _ints(owner: str, name: str, value, length: int | None, minimum: int) -> tuple[int, ...]:
    """`value` (an integer or a list of them) as a tuple, or a ConfigError naming the key."""
    items = list(value) if isinstance(value, (list, tuple)) else [value]
    shape = f"{length} integer(s)" if length else "a non-empty list of integers"
    ok = bool(items) and (length is None or len(items) == length) and all(
        isinstance(v, int) and not isinstance(v, bool) and v >= minimum for v in items)
    if not ok:
        raise ConfigError(f"{owner}: {name}={value!r} must be {shape}, each ≥ {minimum}")
    return tuple(items)


class Tripleplane(Representation):
    """Radial half texture (h_res nodes × C_h), polar difference texture (d_res = radial × φ
    nodes, × C_d), SiLU decoder (hidden) to log f."""

    tags: ClassVar[frozenset[str]] = frozenset({"isotropic", "reciprocal", "fittable", "neural"})
    plugin_name: ClassVar[str] = "tripleplane"
    devices: ClassVar[frozenset[str]] = frozenset({"cpu", "cuda"})

    def __init__(self, h_res: int = DEFAULTS["h_res"], d_res: Sequence[int] = DEFAULTS["d_res"],
                 channels: Sequence[int] = DEFAULTS["channels"], hidden: Sequence[int] = DEFAULTS["hidden"],
                 epochs: int = tf.Recipe.epochs, batch_size: int = tf.Recipe.batch_size,
                 n_samples: int = tf.Recipe.n_samples, lr: float = tf.Recipe.lr,
                 texture_lr: float = tf.Recipe.texture_lr, loss: str = tf.Recipe.loss, beta1: float = tf.Recipe.beta1,
                 ema: float | None = tf.Recipe.ema, precondition: float = tf.Recipe.precondition,
                 init_scale: float = tf.Recipe.init_scale, batch_materials: int = 16,
                 iterations: int | None = tf.Recipe.iterations, resample: bool = tf.Recipe.resample,
                 sampling: str = tf.Recipe.sampling, schedule: str = tf.Recipe.schedule,
                 lr_decay: float = tf.Recipe.lr_decay, lr_decay_every: int = tf.Recipe.lr_decay_every,
                 allow_slow_cpu: bool = False):
        self._configure(dict(h_res=h_res, d_res=d_res, channels=channels, hidden=hidden, epochs=epochs,
                             batch_size=batch_size, n_samples=n_samples, lr=lr, texture_lr=texture_lr, loss=loss,
                             beta1=beta1, ema=ema, precondition=precondition, init_scale=init_scale,
                             batch_materials=batch_materials, iterations=iterations, resample=resample,
                             sampling=sampling, schedule=schedule, lr_decay=lr_decay, lr_decay_every=lr_decay_every,
                             allow_slow_cpu=allow_slow_cpu))

    def _configure(self, params: dict, latent: int = 0, warps: int = 0) -> None:
        """Check `params` (the constructor's keywords) and build the shape and the recipe."""
        name = self.plugin_name
        (h,) = _ints(name, "h_res", params["h_res"], 1, 2)
        d = _ints(name, "d_res", params["d_res"], 2, 2)
        c = _ints(name, "channels", params["channels"], 2, 1)
        hid = _ints(name, "hidden", params["hidden"], None, 1)
        self.shape = tm.Shape(h_res=h, d_res=(d[0], d[1]), channels=(c[0], c[1]), hidden=hid, latent=latent,
                              warps=warps)
        if self.shape.texture_floats() > MAX_TEXTURE_FLOATS:
            raise ConfigError(f"{name}: h_res={h}, d_res={list(d)}, channels={list(c)} need "
                              f"{self.shape.texture_floats():,} texture floats per material, more than the "
                              f"{MAX_TEXTURE_FLOATS:,} allowed")
        batch_materials = params["batch_materials"]
        if not isinstance(batch_materials, int) or isinstance(batch_materials, bool) or batch_materials < 1:
            raise ConfigError(f"{name}: batch_materials={batch_materials!r} must be a positive integer")
        if not isinstance(params["allow_slow_cpu"], bool):
            raise ConfigError(f"{name}: allow_slow_cpu={params['allow_slow_cpu']!r} must be true or false")
        self.recipe = tf.Recipe(**{k: params[k] for k in _RECIPE_KEYS}, owner=name)
        super().__init__(**{**params, "h_res": h, "d_res": list(d), "channels": list(c), "hidden": list(hid)})
        self.batch_materials = batch_materials
        self.allow_slow_cpu = params["allow_slow_cpu"]
        self.tensors: dict[str, torch.Tensor] | None = None
        self.fit_info: dict[str, Any] = {}

    # -- fitting -----------------------------------------------------------------
    @property
    def fit_batch_size(self) -> int:
        if self.device.type == "cpu":
            return self.batch_materials
        return max(self.batch_materials, min(GPU_BATCH_MATERIALS, GPU_PAIRS_PER_STEP // self.recipe.batch_size))

    def _move(self, device: torch.device) -> None:
        if self.tensors is not None:  # an unfitted model holds nothing (and initialises no device)
            self.tensors = {k: v.to(device) for k, v in self.tensors.items()}

    def training_bytes(self, materials: int) -> float:
        """Estimated peak memory of one step over `materials` stacked models: every pair's
        values kept for the backward pass (the inputs, the four bilinear corners' features of
        each texture, the decoder's activations, the outputs), twice over for their gradients."""
        c_h, c_d = self.shape.channels
        per_pair = 6 + 4 * (c_h + c_d) + sum(self.shape.layer_sizes)
        return float(self.recipe.batch_size) * materials * per_pair * 4 * 2

    def cpu_seconds(self) -> float:
        """The estimated time of one material's fit on a CPU (a lower bound, see CPU_TRAIN_FLOP_RATE)."""
        return tf.training_flops(self.recipe, self.shape) / CPU_TRAIN_FLOP_RATE

    def _refuse_slow_cpu_fit(self) -> None:
        """A ConfigError, before anything is computed, for a recipe that would take hours on
        the CPU (unless `allow_slow_cpu`)."""
        if self.device.type != "cpu" or self.allow_slow_cpu:
            return
        seconds = self.cpu_seconds()
        if seconds <= CPU_LIMIT_S:
            return
        r = self.recipe
        if r.iterations is not None:
            steps, knobs = f"iterations={r.iterations:,} steps", "iterations, batch_size"
        else:
            steps = f"epochs={r.epochs} × {r.steps_per_epoch():,} steps (n_samples={r.n_samples:,})"
            knobs = "epochs, n_samples, batch_size"
        raise ConfigError(
            f"{self.plugin_name}: this recipe would fit on the CPU for about {_duration(seconds)} per material "
            f"({steps} of batch_size={r.batch_size:,} pairs × ~{3 * self.shape.flops():,} training FLOPs per pair "
            f"≈ {tf.training_flops(r, self.shape):.2g} FLOPs at an assumed {CPU_TRAIN_FLOP_RATE:.0e} FLOP/s; a CPU "
            f"fit may take at most {_duration(CPU_LIMIT_S)}), holding about "
            f"{self.training_bytes(self.batch_materials) / 2**30:.1f} GiB for {self.batch_materials} materials a "
            f"batch. Run it on a GPU (device=cuda), shorten it ({knobs}), "
            "or set allow_slow_cpu=true to fit on the CPU anyway")

    def fit(self, target: Material, *, seed: int = 0) -> "Tripleplane":
        fitted = self.fit_many([target], seed=seed)[0]
        self.tensors, self.fit_info = fitted.tensors, fitted.fit_info
        return self

    def fit_many(self, targets: Sequence[Material], *, seed: int = 0, progress: bool | str = False) -> list["Tripleplane"]:
        """One fitted model per target, trained together in batches on `self.device` (the
        models live there)."""
        self._refuse_slow_cpu_fit()
        targets = list(targets)
        models: list[Tripleplane] = []
        per_batch = self.fit_batch_size
        for start in range(0, len(targets), per_batch):
            group = targets[start:start + per_batch]
            outcomes = tf.fit_batched([t.table for t in group], [material_seed(seed, t.name) for t in group],
                                      self.shape, self.recipe, sample_seed=seed, progress=progress,
                                      device=self.device)
            for target, outcome in zip(group, outcomes):
                model = self._unfitted()
                model.tensors = outcome.tensors
                model.fit_info = {FIT_LOSS_KEY: outcome.loss, "fitted_to": target.name,
                                  "training_curve": outcome.curve}
                models.append(model)
        return models

    # -- evaluation ----------------------------------------------------------------
    def _eval(self, wi, wo):
        if self.tensors is None:
            raise RuntimeError(f"{self.plugin_name}: evaluate after fit() or load")
        # in wi's dtype, as the CPU figures always were; once per process at a harness's directions
        r_h, r_d, phi = reused.derived(tm.texture_coords, wi, wo)
        dtype = wi.dtype
        stacked = {k: (v.to(dtype)[None, None] if k.startswith("b") else v.to(dtype)[None])
                   for k, v in self.tensors.items()}
        g = tm.log_value(stacked, r_h, r_d, phi)[0]
        return tm.to_value(g)

    def drjit_kernel(self):
        """The model in drjit operations (brdfbench.render), for this exact class only; it
        reads the weights on the host wherever the model lives (Mitsuba's CPU variants)."""
        if type(self) not in (Tripleplane, TriplaneGated) or self.tensors is None:
            return None
        from .drjit_kernels import TripleplaneKernel  # lazy: drjit

        return TripleplaneKernel(self.shape, {k: v.detach().cpu() for k, v in self.tensors.items()})

    # -- persistence and cost -----------------------------------------------------------
    def state_dict(self):
        return {} if self.tensors is None else dict(self.tensors)

    def metadata(self):
        return dict(self.fit_info)

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        model.params = {k: model.params[k] for k in params}
        if tensors:
            model.tensors = _checked(tensors, model.shape, cls.plugin_name)
        model.fit_info = dict(metadata)
        return model

    @property
    def nbytes(self) -> int:
        return 4 * (self.shape.texture_floats() + self.shape.mlp_floats())

    @property
    def texture_nbytes(self) -> int:
        return 4 * self.shape.texture_floats()

    @property
    def flops_per_eval(self) -> int:
        return self.shape.flops()


def _duration(seconds: float) -> str:
    """"40 s", "12 min", "1.9 h"."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.2g} h" if seconds < 36_000 else f"{math.floor(seconds / 3600):,} h"


def _checked(tensors, shape: tm.Shape, name: str) -> dict[str, torch.Tensor]:
    """float32 copies of a model file's tensors, or a ModelFileError naming the tensor."""
    out = {}
    expected = shape.tensor_shapes()
    extra = sorted(set(tensors) - set(expected))
    if extra:
        raise ModelFileError(f"{name} model has unexpected tensors {extra}; expected {sorted(expected)}")
    for key, want in expected.items():
        if key not in tensors:
            raise ModelFileError(f"{name} model lacks tensor {key!r}")
        t = torch.as_tensor(tensors[key]).detach()
        if tuple(t.shape) != want:
            raise ModelFileError(f"{name} model tensor {key!r} has shape {tuple(t.shape)}, expected {want} "
                                 "from the model's params")
        if not t.dtype.is_floating_point or not torch.isfinite(t).all():
            raise ModelFileError(f"{name} model tensor {key!r} holds NaN or Inf, or is not floating point")
        out[key] = t.to(torch.float32).clone()
    for tex in ("h", "d") if shape.warps else ():
        alpha, weight = out[f"warp_{tex}_alpha"], out[f"warp_{tex}_weight"]
        if (alpha < tm.WARP_ALPHA_MIN).any():
            raise ModelFileError(f"{name} model tensor 'warp_{tex}_alpha' = {alpha.tolist()}: every exponent must "
                                 f"be at least {tm.WARP_ALPHA_MIN}")
        if (weight < 0).any() or abs(float(weight.sum()) - 1) > 1e-5:
            raise ModelFileError(f"{name} model tensor 'warp_{tex}_weight' = {weight.tolist()}: must be "
                                 "non-negative and sum to 1 (a partition of unity)")
    return out


#: The triplane-gated defaults (Timonen et al.'s model): tripleplane's textures and decoder plus two
#: warp components per texture and one latent (the uniform-material case of the gating).
GATED_DEFAULTS = {"latent": 1, "warps": 2}


class TriplaneGated(Tripleplane):
    """Timonen et al.'s model: tripleplane's textures storing C × D_s matrices that a spatial latent
    z_s gates (z_h = H z_s; one learned z_s for a spatially uniform material, the path kept
    general for spatially varying ones), each texture read at a learned radial warp
    r' = Σ_k w_k r^{α_k} (w a softmax, α_k = 1/2 + softplus, started near the identity), so
    that resolution gathers at the specular peak and the Fresnel rim."""

    plugin_name: ClassVar[str] = "triplane_gated"

    def __init__(self, h_res: int = DEFAULTS["h_res"], d_res: Sequence[int] = DEFAULTS["d_res"],
                 channels: Sequence[int] = DEFAULTS["channels"], hidden: Sequence[int] = DEFAULTS["hidden"],
                 latent: int = GATED_DEFAULTS["latent"], warps: int = GATED_DEFAULTS["warps"],
                 epochs: int = tf.Recipe.epochs, batch_size: int = tf.Recipe.batch_size,
                 n_samples: int = tf.Recipe.n_samples, lr: float = tf.Recipe.lr,
                 texture_lr: float = tf.Recipe.texture_lr, loss: str = tf.Recipe.loss, beta1: float = tf.Recipe.beta1,
                 ema: float | None = tf.Recipe.ema, precondition: float = tf.Recipe.precondition,
                 init_scale: float = tf.Recipe.init_scale, batch_materials: int = 16,
                 iterations: int | None = tf.Recipe.iterations, resample: bool = tf.Recipe.resample,
                 sampling: str = tf.Recipe.sampling, schedule: str = tf.Recipe.schedule,
                 lr_decay: float = tf.Recipe.lr_decay, lr_decay_every: int = tf.Recipe.lr_decay_every,
                 allow_slow_cpu: bool = False):
        (lat,) = _ints(self.plugin_name, "latent", latent, 1, 1)
        (k,) = _ints(self.plugin_name, "warps", warps, 1, 1)
        self._configure(dict(h_res=h_res, d_res=d_res, channels=channels, hidden=hidden, epochs=epochs,
                             batch_size=batch_size, n_samples=n_samples, lr=lr, texture_lr=texture_lr, loss=loss,
                             beta1=beta1, ema=ema, precondition=precondition, init_scale=init_scale,
                             batch_materials=batch_materials, iterations=iterations, resample=resample,
                             sampling=sampling, schedule=schedule, lr_decay=lr_decay, lr_decay_every=lr_decay_every,
                             allow_slow_cpu=allow_slow_cpu), latent=lat, warps=k)
        self.params = {**self.params, "latent": lat, "warps": k}
