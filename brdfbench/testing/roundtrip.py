"""The save/load round trip that both conformance kits check, written once: a fitted plugin
saved through `brdfbench.modelio` (safetensors and JSON, no pickle) loads back under its
registered name with its params, and then behaves as the saved one did (each kit says what
that means: the same values for a representation, the same samples for a generator)."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any, Callable

from .. import modelio

#: what is saved -> (modelio's save, its load)
_IO: dict[str, tuple[Callable, Callable]] = {
    "model": (modelio.save, modelio.load),
    "generator": (modelio.save_generator, modelio.load_generator),
}


def check_save_load_roundtrip(model: Any, name: str, kind: str, same: Callable[[Any, Any], None]) -> None:
    """Save `model` (a "model" or a "generator", registered as `name`) to a temporary file,
    load it back, and check its name and params; `same(model, loaded)` asserts the rest."""
    save, load = _IO[kind]
    with tempfile.TemporaryDirectory() as tmp:
        path = save(model, name, Path(tmp) / f"{kind}.safetensors")
        loaded_name, loaded = load(path)
    assert loaded_name == name, f"loaded {kind} names itself {loaded_name!r}"
    assert loaded.params == model.params, f"params changed on round trip: {model.params} -> {loaded.params}"
    same(model, loaded)
