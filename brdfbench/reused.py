"""Direction data shared by every material a harness scores.

A harness evaluates every material at the same directions. It registers the tensors it
passes to a model with a provider that computes what depends on the directions alone once
per process, on all of its directions, and hands each registered chunk its rows. A model
asks for such data through `derived(fn, wi, wo, *args)`: for registered tensors it gets
the provider's rows, for any others `fn(wi, wo, *args)` computed afresh, the same values
either way (`fn` must be a pure, row-wise function of the directions). Table cell indices
(brdfbench.merl), the analytic lobes' geometry and the NBRDF input encoding go through it.

An entry holds weak references and is matched by identity (`is`), so a freed tensor whose
id is reused never matches; it is dropped when a tensor changes in place. Timed
evaluations (throughput) never use registered tensors: they measure the whole cost.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any, Callable

import torch

MAX_ENTRIES = 64  # registered pairs kept; the oldest goes first

#: provide(fn, args) → fn(wi, wo, *args) for the registered pair
Provider = Callable[[Callable[..., Any], tuple], Any]


@dataclass(eq=False)
class _Entry:
    wi: weakref.ref
    wo: weakref.ref
    versions: tuple[int, int]
    provide: Provider


_ENTRIES: dict[int, _Entry] = {}


def register(wi: torch.Tensor, wo: torch.Tensor, provide: Provider) -> None:
    """Register (wi, wo): `derived` on these very tensors, while unmodified, takes its
    values from `provide(fn, args)`, which must return `fn(wi, wo, *args)`."""
    key = id(wi)
    forget = lambda ref, key=key: _forget(key, ref)  # noqa: E731
    _ENTRIES.pop(key, None)
    _ENTRIES[key] = _Entry(weakref.ref(wi, forget), weakref.ref(wo, forget), (wi._version, wo._version), provide)
    while len(_ENTRIES) > MAX_ENTRIES:
        _ENTRIES.pop(next(iter(_ENTRIES)))


def _forget(key: int, ref: weakref.ref) -> None:
    entry = _ENTRIES.get(key)
    if entry is not None and (ref is entry.wi or ref is entry.wo):
        del _ENTRIES[key]


def provider(wi: torch.Tensor, wo: torch.Tensor) -> Provider | None:
    """The provider registered for exactly these tensors, unmodified since; else None."""
    entry = _ENTRIES.get(id(wi))
    if entry is None or entry.wi() is not wi or entry.wo() is not wo:
        return None
    if (wi._version, wo._version) != entry.versions:
        del _ENTRIES[id(wi)]
        return None
    return entry.provide


def derived(fn: Callable[..., Any], wi: torch.Tensor, wo: torch.Tensor, *args) -> Any:
    """fn(wi, wo, *args), from the registered provider where (wi, wo) are registered."""
    provide = provider(wi, wo)
    return fn(wi, wo, *args) if provide is None else provide(fn, args)
