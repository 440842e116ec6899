"""Files a cell leaves beside the store (rendered images, lobe slices), indexed by
configuration and material, so a report finds them without knowing a harness's layout.

`<results>/artifacts/<config hash>/<material>.json` maps a kind ("image", "reference",
"lobes", …) to a path relative to the results folder plus what describes it (spp,
sampler). One cell's worker writes its own entry (atomically), so writers never meet.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from .atomic import replacing

FOLDER = "artifacts"


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.@+-]", "_", name)


def index_path(results_dir: Path, config_hash: str, material: str) -> Path:
    return Path(results_dir) / FOLDER / _safe(config_hash) / f"{_safe(material)}.json"


def record(results_dir: Path, config_hash: str, material: str, kind: str, path: Path, **meta: Any) -> None:
    """Add (or replace) one artifact of a cell in its index."""
    index = index_path(results_dir, config_hash, material)
    index.parent.mkdir(parents=True, exist_ok=True)
    entries = lookup(results_dir, config_hash, material)
    try:
        relative = str(Path(path).resolve().relative_to(Path(results_dir).resolve()))
    except ValueError:
        relative = str(Path(path).resolve())
    entries[kind] = {"path": relative, **meta}
    with replacing(index) as tmp:
        tmp.write_text(json.dumps(entries, indent=1, sort_keys=True), encoding="utf-8")


def lookup(results_dir: Path, config_hash: str, material: str) -> dict[str, dict[str, Any]]:
    """A cell's artifacts (kind → entry), {} where it left none or its index is unreadable."""
    try:
        value = json.loads(index_path(results_dir, config_hash, material).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return value if isinstance(value, dict) else {}


def saved_model_path(results_dir: Path, fingerprint: str, label: str, material: str) -> Path:
    """Where `save_models=true` keeps a cell's fitted model."""
    return Path(results_dir) / "models" / fingerprint / label / f"{material}.safetensors"


def discard(results_dir: Path, config_hash: str, material: str) -> None:
    """Remove a cell's artifacts (its index and the files it lists inside the results folder,
    but the shared reference image), for a cell that could not be stored: nothing is left that the store does not know."""
    root = Path(results_dir).resolve()
    index = index_path(results_dir, config_hash, material)
    for kind, entry in lookup(results_dir, config_hash, material).items():
        if kind == "reference":  # the target's image, shared with other configurations
            continue
        path = Path(entry.get("path", "")) if isinstance(entry, dict) else None
        if not path or not str(path):
            continue
        path = (root / path).resolve()
        if root not in path.parents:
            continue
        for each in (path, *(path.with_name(entry[k]) for k in ("png",) if isinstance(entry.get(k), str))):
            try:
                each.unlink(missing_ok=True)
            except OSError:
                pass
    try:
        index.unlink(missing_ok=True)
        index.parent.rmdir()  # only when empty
    except OSError:
        pass
