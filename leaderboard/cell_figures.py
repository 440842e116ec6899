"""Figures from the files cells leave beside the store (`brdfbench.artifacts`): polar lobe
plots of the accuracy harness's in-plane slices, and image grids of rendered scenes with
their error maps. A missing or unreadable file leaves its figure out with a note, never
fails the report.

Materials shown: up to `MAX_MATERIALS` per section, one per category first (the first by
name in each), so every kind of material is seen once before any is seen twice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brdfbench import artifacts

from . import lobe_svg
from .view import TableSection

MAX_MATERIALS = 6
LOBE_FLOOR = 1e-3  # 1/sr: the plots' radial axis starts here (log scale)
REL_ERROR_MAX = 1.0  # the relative-error map saturates at 100 %
FOLDER = "report-images"


def chosen_materials(section: TableSection, categories: dict[str, str]) -> list[str]:
    by_category: dict[str, list[str]] = {}
    for m in section.materials:
        by_category.setdefault(categories.get(m, "unknown"), []).append(m)
    rounds = [sorted(v) for _, v in sorted(by_category.items())]
    out: list[str] = []
    depth = 0
    while len(out) < MAX_MATERIALS and any(depth < len(r) for r in rounds):
        out += [r[depth] for r in rounds if depth < len(r)][:MAX_MATERIALS - len(out)]
        depth += 1
    return out


# --------------------------------------------------------------------------- lobes


@dataclass(frozen=True)
class LobeFigure:
    material: str
    svg: str  # inline SVG markup
    series: list[int]  # indices into the section's rows, in legend order
    missing: list[str]  # labels without slices for this material


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def _radius(values: np.ndarray) -> np.ndarray:
    """Radial coordinate: decades above the floor, log scale."""
    return np.log10(np.maximum(values, LOBE_FLOOR) / LOBE_FLOOR)


def lobe_figures(section: TableSection, results_dir: Path, categories: dict[str, str], plot_prefix: str) -> list[LobeFigure]:
    from brdfbench.harness import lobes

    out = []
    for material in chosen_materials(section, categories):
        docs: dict[int, dict] = {}
        missing = []
        for k, row in enumerate(section.rows):
            entry = artifacts.lookup(results_dir, row.config_hash, material).get("lobes")
            doc = lobes.read(Path(results_dir) / entry["path"]) if entry else None
            if doc is None:
                missing.append(row.label)
            else:
                docs[k] = doc
        if not docs:
            continue
        out.append(LobeFigure(material, _lobe_figure(docs, f"{plot_prefix}-{len(out)}"), sorted(docs),
                              missing))
    return out


def _lobe_figure(docs: dict[int, dict], plot_id: str) -> str:
    first = docs[min(docs)]
    theta_o = np.radians(np.asarray(first["theta_o_deg"], dtype=float))
    table = [_radius(_luminance(np.asarray(t, dtype=float))) for t in first["table"]]
    models = {k: [_radius(_luminance(np.asarray(m, dtype=float))) for m in doc["model"]] for k, doc in docs.items()}
    return lobe_svg.lobe_panels(first["theta_i_deg"], theta_o, table, models, plot_id,
                                int(math.log10(LOBE_FLOOR)))


# --------------------------------------------------------------------------- image grids


@dataclass(frozen=True)
class ImageCell:
    label: str
    image: str | None  # paths relative to the results folder (None: not saved)
    flip: str | None
    relative: str | None
    note: str = ""


@dataclass(frozen=True)
class ImageRow:
    material: str
    reference: str | None
    cells: list[ImageCell]
    caption: str


def _fresh(target: Path, *sources: Path) -> bool:
    try:
        t = target.stat().st_mtime
        return all(s.stat().st_mtime <= t for s in sources)
    except OSError:
        return False


def _write_map(path: Path, values: np.ndarray, cmap: str, vmax: float) -> None:
    from matplotlib import colormaps
    from PIL import Image

    from brdfbench.atomic import replacing

    rgba = colormaps[cmap](np.clip(values / vmax, 0, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    with replacing(path) as tmp:
        Image.fromarray((rgba[..., :3] * 255 + 0.5).astype(np.uint8)).save(tmp, format="PNG")


def error_maps(results_dir: Path, image_exr: Path, reference_exr: Path, stem: str, exposure: float) -> tuple[str, str]:
    """FLIP map (LDR) and relative-error heat map of one render against its reference, as
    PNGs under `<results>/report-images/` (reused while newer than both renders)."""
    import torch

    from brdfbench.images import read_exr
    from brdfbench_metrics.image_functional import flip

    folder = Path(results_dir) / FOLDER
    flip_png, rel_png = folder / f"{stem}.flip.png", folder / f"{stem}.relerr.png"
    if not (_fresh(flip_png, image_exr, reference_exr) and _fresh(rel_png, image_exr, reference_exr)):
        image, reference = read_exr(image_exr), read_exr(reference_exr)
        _, fmap = flip(image, reference, space="ldr", exposure=exposure, return_map=True)
        _write_map(flip_png, fmap.numpy(), "magma", 1.0)
        lum = lambda x: (x.to(torch.float64) @ torch.tensor([0.2126, 0.7152, 0.0722], dtype=torch.float64)).numpy()
        ref = lum(reference)
        rel = np.abs(lum(image) - ref) / np.maximum(ref, 1e-3 * max(float(ref.max()), 1e-12))
        _write_map(rel_png, rel, "inferno", REL_ERROR_MAX)
    root = Path(results_dir)
    return str(flip_png.relative_to(root)), str(rel_png.relative_to(root))


def image_rows(section: TableSection, results_dir: Path, categories: dict[str, str]) -> list[ImageRow]:
    results_dir = Path(results_dir)
    out = []
    for material in chosen_materials(section, categories):
        reference, meta, cells = None, {}, []
        for row in section.rows:
            entries = artifacts.lookup(results_dir, row.config_hash, material)
            image, ref = entries.get("image"), entries.get("reference")
            if not image or not ref:
                cells.append(ImageCell(row.label, None, None, None, "no saved render"))
                continue
            image_exr, ref_exr = results_dir / image["path"], results_dir / ref["path"]
            if not (image_exr.is_file() and ref_exr.is_file()):
                cells.append(ImageCell(row.label, None, None, None, "render file missing"))
                continue
            meta = meta or image
            reference = reference or str(ref_exr.with_suffix(".png").relative_to(results_dir))
            try:
                flip_png, rel_png = error_maps(results_dir, image_exr, ref_exr,
                                               f"{row.config_hash}-{artifacts._safe(material)}",
                                               float(image.get("exposure") or 0.0))
            except Exception as exc:  # an unreadable EXR: say so in place of the maps
                cells.append(ImageCell(row.label, str(image_exr.with_suffix(".png").relative_to(results_dir)), None,
                                       None, f"error maps failed: {exc}"))
                continue
            cells.append(ImageCell(row.label, str(image_exr.with_suffix(".png").relative_to(results_dir)), flip_png,
                                   rel_png))
        if reference is None:
            continue
        how = [f"simulator {meta.get('simulator')}"]
        if meta.get("spp"):
            how.append(f"shown at {meta['spp']} spp, sampler {meta.get('sampler')}")
        if meta.get("measured_spp"):
            how.append(f"metrics measured at {meta['measured_spp']} spp")
        out.append(ImageRow(material, reference, cells, ", ".join(how)))
    return out
