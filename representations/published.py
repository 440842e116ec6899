"""`published_fit`: the literature's own analytic fits of MERL materials, evaluated as published.

No fitting: `fit(target)` looks the target's name (or `material`) up in a published-fit file
(`source`: a file shipped in `published_fits/`, e.g. `ngan_ward`, `low_cooktorrance_e2`,
`bagher_sgd`, or a path to a `.fit` file in the same format) and evaluates that fit with the
analytic model whose paper it comes from (the class listing the file's model name in its
`PUBLISHED_AS`; `model` picks another reading where the convention is disputed). It shows
what the published parameters score on our metrics.

The published fits were made against the measured MERL data; a dataset of other tables with
MERL names (`nbrdf_release`'s networks approximating MERL) is a close stand-in, not the
target they were fitted to. A material without a published fit, a malformed line, a model
without an implementation here, or a parameter outside its model's domain fails that
material with a message naming the file and line; the other materials are unaffected.
"""

from __future__ import annotations

import importlib
from functools import lru_cache
from pathlib import Path
from typing import Any, ClassVar

import torch

from brdfbench.errors import ConfigError, DataError, ModelFileError
from brdfbench.protocols.representation import Material, Representation

from .analytic import AnalyticBRDF
from .published_parse import FitFile, read_fit_file

FITS_DIR = Path(__file__).with_name("published_fits")
#: Modules whose AnalyticBRDF classes evaluate published fits (their PUBLISHED_AS names).
FORM_MODULES = (
    "brdfbench_representations.ngan_models",
    "brdfbench_representations.microfacet_models",
    "brdfbench_representations.sgd",
    "brdfbench_representations.he_model",
)
#: Models of the shipped files without an implementation here, and why.
NOT_IMPLEMENTED: dict[str, str] = {}


class NoPublishedFit(ConfigError):
    """This material has no usable published fit in the source: its cell fails, the run goes on
    (a ConfigError, not bad data: the file itself was read)."""


def shipped_sources() -> dict[str, Path]:
    """Source name (the file's stem, lower case) -> shipped `.fit` file."""
    return {p.stem.lower(): p for p in sorted(FITS_DIR.glob("*.fit"))}


@lru_cache(maxsize=None)
def published_readings() -> dict[str, tuple[type[AnalyticBRDF], ...]]:
    """Published model name (BBM's, as in the files) -> every class that evaluates it, the
    default first (module order, then definition order). Several where the convention is
    disputed: NganBlinnPhong by `phong` (BBM's mirror-lobe reading) and `blinn_phong_ngan`."""
    forms: dict[str, list[type[AnalyticBRDF]]] = {}
    for module_name in FORM_MODULES:
        module = importlib.import_module(module_name)
        for obj in vars(module).values():
            if isinstance(obj, type) and issubclass(obj, AnalyticBRDF) and obj.__module__ == module_name:
                for name in getattr(obj, "PUBLISHED_AS", ()):
                    forms.setdefault(name, []).append(obj)
    return {name: tuple(classes) for name, classes in forms.items()}


def published_forms() -> dict[str, type[AnalyticBRDF]]:
    """Published model name -> the class that evaluates it by default."""
    return {name: classes[0] for name, classes in published_readings().items()}


def reading_names() -> dict[str, type[AnalyticBRDF]]:
    """Registered model name -> class, for every class that evaluates some published fits."""
    return {c.NAME: c for classes in published_readings().values() for c in classes}


def resolve_source(source: Any) -> Path:
    """The `.fit` file a `source` parameter names; ConfigError naming the key otherwise."""
    if not isinstance(source, str) or not source.strip():
        raise ConfigError(f"published_fit: source must be a published-fit name or a .fit path, got {source!r}")
    shipped = shipped_sources()
    if source.lower() in shipped:
        return shipped[source.lower()]
    if source.endswith(".fit"):
        path = Path(source).expanduser()
        if not path.is_file():
            raise ConfigError(f"published_fit: source {source!r}: no such .fit file")
        return path
    import difflib

    close = difflib.get_close_matches(source.lower(), list(shipped), n=1, cutoff=0.5)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    raise ConfigError(f"published_fit: unknown source {source!r}{hint} (one of {', '.join(shipped)}, or a path to a .fit file)")


@lru_cache(maxsize=32)
def _load(path: str, mtime_ns: int) -> FitFile:
    return read_fit_file(Path(path))


def load_source(source: str) -> FitFile:
    path = resolve_source(source)
    return _load(str(path), path.stat().st_mtime_ns)


def source_model(source: str) -> str | None:
    """The registered name of the model a source's fits are evaluated with (e.g. "ward" for
    `ngan_ward`), or None where no brdfbench model evaluates them (a user's file of another model)."""
    fits = load_source(source)
    names = {f.model for f in fits.fits.values()}
    forms = published_forms()
    known = {forms[n].NAME for n in names if n in forms}
    return known.pop() if len(known) == 1 else None


class PublishedFit(Representation):
    """A published analytic fit of the target's MERL material, looked up by name, evaluated as published."""

    tags: ClassVar[frozenset[str]] = frozenset({"isotropic", "reciprocal", "fittable", "analytic"})
    devices = frozenset({"cpu", "cuda"})

    def __init__(self, source: str = "bagher_sgd", material: str | None = None, model: str | None = None):
        if material is not None and (not isinstance(material, str) or not material):
            raise ConfigError(f"published_fit: material must be a MERL material name or null, got {material!r}")
        resolve_source(source)
        if model is not None and model not in reading_names():
            import difflib

            known = sorted(reading_names())
            close = difflib.get_close_matches(str(model), known, n=1, cutoff=0.5)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ConfigError(f"published_fit: model={model!r} evaluates no published fits{hint} (one of {', '.join(known)}, "
                              "or null: the source's own)")
        # model=None (the source's own reading) is left out of params: configurations written before the key stay the same
        super().__init__(source=source, material=material, **({} if model is None else {"model": model}))
        self.source = source
        self.material = material
        self.reading = model
        self.model: AnalyticBRDF | None = None
        self.fit_info: dict[str, Any] = {}

    def preflight(self) -> None:
        fits = load_source(self.source)
        if self.reading is not None:
            readable = {c.NAME for f in fits.fits.values() for c in published_readings().get(f.model, ())}
            if self.reading not in readable:
                models = sorted({f.model for f in fits.fits.values()})
                raise ConfigError(f"published_fit: model={self.reading!r} does not evaluate {self.source}'s "
                                  f"{', '.join(models)} fits (those: {', '.join(sorted(readable)) or 'none here'})")

    def fit(self, target: Material, *, seed: int = 0) -> "PublishedFit":
        fits = load_source(self.source)
        name = self.material or target.name
        try:
            entry = fits.lookup(name)
        except DataError as exc:
            raise NoPublishedFit(str(exc)) from None
        where = f"{fits.path}:{entry.line}"
        forms = published_forms()
        if entry.model not in forms:
            why = NOT_IMPLEMENTED.get(entry.model, f"no brdfbench model evaluates {entry.model!r} fits")
            raise NoPublishedFit(f"{where}: {name}: {why} (models with published fits here: {', '.join(sorted(forms))})")
        cls = forms[entry.model]
        if self.reading is not None:
            chosen = [c for c in published_readings()[entry.model] if c.NAME == self.reading]
            if not chosen:
                raise NoPublishedFit(f"{where}: {name}: model={self.reading!r} does not evaluate {entry.model!r} fits")
            cls = chosen[0]
        try:
            coeffs = cls.from_published(entry.model, list(entry.diffuse), entry.params)
            model = cls().set_coefficients(**coeffs)
        except (ValueError, ConfigError) as exc:
            raise NoPublishedFit(f"{where}: {name}: {exc}") from None
        self.model = model if self.device.type == "cpu" else model.to(self.device)
        self.fit_info = {"published_model": entry.model, "model": cls.NAME, "published_material": name,
                         "source": fits.source, "citation": fits.citation, "line": entry.line}
        return self

    def _fitted(self) -> AnalyticBRDF:
        if self.model is None:
            raise RuntimeError("published_fit: fit(target) first (it looks up the target's published fit)")
        return self.model

    def _eval(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        return self._fitted()._eval(wi, wo)

    def _move(self, device) -> None:
        if self.model is not None:
            self.model = self.model.to(device)

    def drjit_kernel(self):
        """The kernel of the model the fit is evaluated with."""
        return None if self.model is None else self.model.drjit_kernel()

    # -- persistence and cost --------------------------------------------------------
    def state_dict(self) -> dict[str, torch.Tensor]:
        return {} if self.model is None else self.model.state_dict()

    def metadata(self) -> dict[str, Any]:
        return dict(self.fit_info)

    @classmethod
    def from_state(cls, params, tensors, metadata):
        out = cls(**params)
        if not tensors:
            return out
        name = metadata.get("model")
        by_name = reading_names()
        if name not in by_name:
            raise ModelFileError(f"published_fit model: unknown model {name!r} in the metadata; expected one of {', '.join(sorted(by_name))}")
        out.model = by_name[name].from_state({}, tensors, {})
        out.fit_info = dict(metadata)
        return out

    @property
    def flops_per_eval(self) -> int:
        return 0 if self.model is None else self.model.flops_per_eval
