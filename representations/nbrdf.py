"""Neural BRDFs: NBRDF (Sztrajman et al. 2021) and the naive direction-input MLP.

`nbrdf` is an MLP 6 → 21 → 21 → 3 (hidden sizes configurable) on the Rusinkiewicz
encoding (see brdfbench.nbrdf.network); `naive_mlp` is the same budget fed (ωi, ωo) directly, the
baseline of Timonen et al. Both fit many materials at once (`fit_many`, see
nbrdf_fit.py); the runner hands them `batch_materials` materials per call.

Initialisation (`init`): "random" draws Glorot weights from a seed derived from the run
seed and the material name, so a material's fit does not depend on its batch-mates;
"shared" fits the first material this model sees from random weights and starts every
later material from that network, which keeps the weight vectors of different materials
aligned for generators that learn over them; a path starts every material from the
network in that file (any format `brdfbench.nbrdf.formats.read_network` reads).

The network itself (layout, encodings, forward pass) is the core's `brdfbench.nbrdf`,
which the `nbrdf_release` dataset uses too; a fitted model exposes it as `network`.
A model made from a converted network (`from_network`) records only what is true of it:
its architecture and units as params, its encoding and source file as metadata.
"""

from __future__ import annotations

import zlib
from pathlib import Path
from typing import Any, ClassVar, Sequence

import torch

from brdfbench import reused
from brdfbench.errors import BrdfbenchError, ConfigError, ModelFileError
from brdfbench.nbrdf import network as net
from brdfbench.nbrdf.formats import read_network
from brdfbench.nbrdf.network import Network
from brdfbench.protocols.representation import FIT_LOSS_KEY, Material, Representation

from .nbrdf_fit import Recipe, fit_batched

DEFAULT_HIDDEN = net.PUBLISHED_HIDDEN
DEFAULT_BATCH_MATERIALS = 16
#: Materials fitted together on a GPU at least: a step there costs about the same for 16 or
#: 128 stacked networks (a fit does not depend on its batch-mates, so only speed changes).
GPU_BATCH_MATERIALS = 128


def material_seed(seed: int, name: str) -> int:
    return (seed * 1_000_003 + zlib.crc32(name.encode("utf-8"))) % 2**63


def _checked_weights(tensors, hidden, where: str) -> dict[str, torch.Tensor]:
    """The float32 weights of a 6 → hidden… → 3 network from `tensors`, or a ModelFileError
    naming `where` and the tensor that is missing, misshapen, not floating point or not finite."""
    out = {}
    for key, shape in net.weight_shapes(hidden).items():
        if key not in tensors:
            raise ModelFileError(f"{where} lacks tensor {key!r}")
        t = torch.as_tensor(tensors[key]).detach()
        if tuple(t.shape) != shape:
            raise ModelFileError(f"{where} tensor {key!r} has shape {tuple(t.shape)}, expected {shape}")
        if not t.dtype.is_floating_point:
            raise ModelFileError(f"{where} tensor {key!r} has dtype {t.dtype}, expected floating point")
        if not torch.isfinite(t).all():
            raise ModelFileError(f"{where} tensor {key!r} holds NaN or Inf")
        out[key] = t.to(torch.float32).clone()
    return out


def _check_scale(model: str, scale: torch.Tensor, raw_units: bool) -> None:
    """A saved `output_scale` must be the constant of the model's units."""
    want = net.units_scale(raw_units)
    if not scale.dtype.is_floating_point or not torch.isfinite(scale).all():
        raise ModelFileError(f"{model} model tensor 'output_scale' holds NaN or Inf: {scale.tolist()}")
    if tuple(scale.shape) != (3,) or not torch.allclose(scale.to(torch.float32), want, rtol=1e-6, atol=0.0):
        raise ModelFileError(f"{model} model tensor 'output_scale' is {scale.tolist()}; raw_units={raw_units} "
                             f"means {want.tolist()}")


class NeuralBRDF(Representation):
    """An MLP BRDF; subclasses choose the input encoding."""

    features: ClassVar[str] = "rusinkiewicz"
    plugin_name: ClassVar[str] = "nbrdf"
    devices = frozenset({"cpu", "cuda"})
    #: `loss` where a config leaves it out (null); see nbrdf_fit and NaiveMLP
    default_loss: ClassVar[str] = Recipe.loss

    def __init__(
        self,
        hidden: Sequence[int] = DEFAULT_HIDDEN,
        epochs: int = Recipe.epochs,
        batch_size: int = Recipe.batch_size,
        lr: float = Recipe.lr,
        schedule: str = Recipe.schedule,
        n_samples: int = Recipe.n_samples,
        output: str = Recipe.output,
        patience: int | None = Recipe.patience,
        min_improvement: float = Recipe.min_improvement,
        sampling: str = Recipe.sampling,
        loss: str | None = None,
        batch_materials: int = DEFAULT_BATCH_MATERIALS,
        init: str = "random",
        raw_units: bool = False,
    ):
        name = self.plugin_name
        if loss is None:
            loss = self.default_loss
        try:
            hidden = [int(h) for h in hidden]
        except (TypeError, ValueError):
            raise ConfigError(f"{name}: hidden={hidden!r} must be a list of layer widths") from None
        if not hidden or any(h < 1 for h in hidden):
            raise ConfigError(f"{name}: hidden={hidden!r} must be a non-empty list of positive layer widths")
        if not isinstance(batch_materials, int) or batch_materials < 1:
            raise ConfigError(f"{name}: batch_materials={batch_materials!r} must be a positive integer")
        if not isinstance(init, str) or not init:
            raise ConfigError(f"{name}: init={init!r} must be 'random', 'shared' or a path to a network file")
        super().__init__(
            hidden=hidden, epochs=epochs, batch_size=batch_size, lr=lr, schedule=schedule, n_samples=n_samples,
            output=output, patience=patience, min_improvement=min_improvement, sampling=sampling,
            loss=loss, batch_materials=batch_materials, init=init, raw_units=bool(raw_units),
        )
        self.hidden = hidden
        self.raw_units = bool(raw_units)
        self.batch_materials = batch_materials
        self.init = init
        self._fit_params = dict(self.params)  # what a model fitted by this one was made with
        self.recipe = Recipe(epochs=epochs, batch_size=batch_size, lr=lr, schedule=schedule, n_samples=n_samples,
                             output=output, patience=patience, min_improvement=min_improvement, sampling=sampling,
                             loss=loss)
        self.output_scale = net.units_scale(self.raw_units)
        self.weights: dict[str, torch.Tensor] | None = None
        self.fit_info: dict[str, Any] = {}
        self._anchor: dict[str, torch.Tensor] | None = None  # the start of every fit, once known

    @property
    def network(self) -> Network | None:
        """The fitted weights as the shared NBRDF network (None before a fit)."""
        if self.weights is None:
            return None
        return Network(weights=self.weights, features=self.features, raw_units=self.raw_units)

    def preflight(self) -> None:
        """A network file named by init= is read now, so a missing or wrong one fails at validation."""
        if self.init not in ("random", "shared"):
            try:
                self._anchor = self._read_init(Path(self.init))
            except BrdfbenchError as exc:
                raise ConfigError(f"{self.plugin_name}: init: {exc}") from None

    def _read_init(self, path: Path) -> dict[str, torch.Tensor]:
        network = read_network(path, hidden=self.hidden, features=self.features, raw_units=self.raw_units)
        if network.hidden != self.hidden:
            raise ConfigError(f"{self.plugin_name}: init network {path} has hidden sizes {network.hidden}, "
                              f"this model {self.hidden}")
        if network.features != self.features:
            raise ModelFileError(f"{path}: a {network.features!r}-input network cannot start a {self.features!r}-input model")
        return network.weights

    # -- converted networks ---------------------------------------------------------
    @classmethod
    def from_network(cls, network: Network) -> "NeuralBRDF":
        """A model holding a network's weights as they are (no fit): its params are the
        architecture and units only, its metadata the encoding and the source file."""
        where = network.source or "network"
        if network.features != cls.features:
            raise ModelFileError(f"{where}: a {network.features!r}-input network is not a {cls.plugin_name} "
                                 f"({cls.features!r} inputs)")
        model = cls(hidden=network.hidden, raw_units=network.raw_units)
        model.params = {"hidden": model.hidden, "raw_units": model.raw_units}
        model.weights = _checked_weights(network.weights, model.hidden, f"{where}: {cls.plugin_name} network")
        model.fit_info = {"source": network.source} if network.source else {}
        return model

    # -- fitting -----------------------------------------------------------------
    @property
    def fit_batch_size(self) -> int:
        return self.batch_materials if self.device.type == "cpu" else max(self.batch_materials, GPU_BATCH_MATERIALS)

    def _move(self, device: torch.device) -> None:
        if self.weights is not None:  # an unfitted model holds nothing (and initialises no device)
            self.weights = {k: v.to(device) for k, v in self.weights.items()}
            self.output_scale = self.output_scale.to(device)

    def fit(self, target: Material, *, seed: int = 0) -> "NeuralBRDF":
        fitted = self.fit_many([target], seed=seed)[0]
        self.weights, self.fit_info = fitted.weights, fitted.fit_info
        return self

    def fit_many(self, targets: Sequence[Material], *, seed: int = 0, progress: bool | str = False) -> list["NeuralBRDF"]:
        """One fitted model per target, all trained together in batched passes."""
        targets = list(targets)
        if self._anchor is None and self.init not in ("random", "shared"):
            self._anchor = self._read_init(Path(self.init))
        models: list[NeuralBRDF | None] = [None] * len(targets)
        pending = list(range(len(targets)))
        if self.init == "shared" and self._anchor is None and targets:
            first = self._fit_group([targets[0]], [self._random_init(targets[0], seed)], seed, progress)[0]
            self._anchor = first.weights
            models[0] = first
            pending = pending[1:]
        for start in range(0, len(pending), self.fit_batch_size):
            group = [targets[i] for i in pending[start:start + self.fit_batch_size]]
            inits = [self._anchor if self._anchor is not None else self._random_init(t, seed) for t in group]
            for i, model in zip(pending[start:start + self.fit_batch_size], self._fit_group(group, inits, seed, progress)):
                models[i] = model
        return models

    def _random_init(self, target: Material, seed: int) -> dict[str, torch.Tensor]:
        return net.glorot_init(self.hidden, torch.Generator().manual_seed(material_seed(seed, target.name)))

    def _fit_group(self, group, inits, seed, progress) -> list["NeuralBRDF"]:
        outcomes = fit_batched(
            [t.table for t in group], inits, features=self.features, recipe=self.recipe,
            output_scale=self.output_scale, sample_seed=seed, progress=progress, device=self.device,
        )
        fitted = []
        for target, outcome in zip(group, outcomes):
            model = type(self)(**self._fit_params)
            if self.device.type != "cpu":
                model.to(self.device)
            model._anchor = self._anchor
            model.weights = outcome.weights
            if self.device.type != "cpu":
                model.output_scale = model.output_scale.to(self.device)
            model.fit_info = {FIT_LOSS_KEY: outcome.loss, "epochs": outcome.epochs, "fitted_to": target.name}
            if self.recipe.loss in ("l1_or_l2", "l1_then_l2"):
                model.fit_info["descended"] = outcome.descended
                model.fit_info["losses_fitted"] = list(outcome.fitted)
            if outcome.collapse is not None:
                model.fit_info["collapse_ratio"] = outcome.collapse
            fitted.append(model)
        return fitted

    # -- evaluation ----------------------------------------------------------------
    def _eval(self, wi, wo):
        if self.weights is None:
            raise RuntimeError(f"{self.plugin_name}: evaluate after fit() or load")
        return net.forward(self.weights, reused.derived(net.encode, wi, wo, self.features), self.output_scale)

    def drjit_kernel(self):
        """The network in drjit operations (brdfbench.render), for this exact class only:
        a subclass may change `_eval`."""
        if type(self) not in (NBRDF, NaiveMLP) or self.weights is None:
            return None
        from .drjit_kernels import MLPKernel  # lazy: drjit

        return MLPKernel(self.network, self.plugin_name)

    # -- persistence and cost -----------------------------------------------------------
    def state_dict(self):
        if self.weights is None:
            return {}
        return {**self.weights, "output_scale": self.output_scale}

    def metadata(self):
        return dict(self.fit_info, features=self.features)

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        model.params = {k: model.params[k] for k in params}  # what the file records, no more
        if tensors:
            model.weights = _checked_weights(tensors, model.hidden, f"{cls.plugin_name} model")
            if "output_scale" in tensors:
                _check_scale(cls.plugin_name, tensors["output_scale"], model.raw_units)
        model.fit_info = {k: v for k, v in metadata.items() if k != "features"}
        return model

    @property
    def nbytes(self) -> int:
        return 4 * net.n_weights(self.hidden)  # float32 weights; the 3 channel scales are a constant of the units

    @property
    def flops_per_eval(self) -> int:
        encoding = net.RUSINKIEWICZ_FLOPS if self.features == "rusinkiewicz" else 0
        return encoding + net.mlp_flops(self.hidden)


class NBRDF(NeuralBRDF):
    """6 → 21 → 21 → 3 on the Rusinkiewicz encoding (isotropic by construction)."""

    tags = frozenset({"isotropic", "fittable", "neural"})
    features = "rusinkiewicz"
    plugin_name = "nbrdf"


class NaiveMLP(NeuralBRDF):
    """The same network fed (ωi, ωo) directly: neither isotropic nor reciprocal by construction.

    Trained on the NBRDF loss alone it collapses on sharp lobes (issue 16): fed raw directions
    it must first find the half-vector alignment, and on a sharp lobe only about 1 % of the
    training pairs lie near the peak. The L1 loss's gradient has the same magnitude for every
    pair, so the 99 % off the peak pin the model at the diffuse-only (median) solution,
    l1_log_cos equal to lambert's, and the early stop ends it there. The squared log error's
    gradient grows with the residual, so the peak pairs (residuals of several log units)
    dominate it and no material collapses, but on smooth materials it ends less accurate in
    L1 terms. So by default (`loss=l1_then_l2`) each material is fitted with L1 and refitted
    with L2 from the same start only where the L1 fit collapsed, its final L1 loss above a
    quarter of the best constant BRDF's (`nbrdf_fit.collapse_ratio`): a collapsed fit does no
    better than the diffuse-only prediction (ratio 0.9–0.99 for the four collapses of the
    synthetic and release sets, 0.36–0.39 for the partial ones, black-obsidian and
    two-layer-silver), a healthy fit at most about a quarter of it. Of the two fits it keeps
    the lower final L1 training loss: the model's own objective, no held-out data. A false
    alarm costs a fit, never accuracy, hence the low threshold. `loss=l1_or_l2` fits both
    everywhere (it also keeps L2 where L2 beats a healthy fit by a few per cent: nickel and
    tungsten-carbide of the release).
    A switch from one loss to the other within one fit was tried and dropped: at the switch
    Adam's moments, averaged over the other loss's gradients, either kicked the network off
    its solution (fabrics ended worse than lambert) or, restarted, let L1 pull a found lobe
    back to the median (the black-obsidian fit).
    tests/integration/test_naive_mlp_sharp.py holds a sharp synthetic material to it."""

    tags = frozenset({"fittable", "neural"})
    features = "directions"
    plugin_name = "naive_mlp"
    default_loss = "l1_then_l2"
