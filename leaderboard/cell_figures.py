"""Figures from the files cells leave beside the store (`brdfbench.artifacts`): polar lobe
plots of the accuracy harness's in-plane slices, and image grids of rendered scenes with
their error maps. A missing or unreadable file leaves its figure out with a note, never
fails the report.

Materials shown: up to `MAX_MATERIALS` per section, one per category first (the first by
name in each), so every kind of material is seen once before any is seen twice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from brdfbench import artifacts

from . import lobe_svg
from .view import TableSection
from brdfbench.atomic import replacing
from brdfbench.harness import lobes

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
class LobePanel:
    row: int  # index into the section's rows
    svg: str  # inline SVG markup: this configuration's slices, the table's on top


@dataclass(frozen=True)
class LobeFigure:
    """One material's small multiples: a panel per configuration, the references (the
    target itself, which the dashed table line is) left out, on one shared radial scale."""

    material: str
    theta_i_deg: list[float]
    panels: list[LobePanel]
    missing: list[str]  # labels without slices for this material


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def _radius(values: np.ndarray) -> np.ndarray:
    """Radial coordinate: decades above the floor, log scale."""
    return np.log10(np.maximum(values, LOBE_FLOOR) / LOBE_FLOOR)


def _slices(doc: dict, key: str) -> list[np.ndarray]:
    return [_luminance(np.asarray(t, dtype=float)) for t in doc[key]]


def lobe_figures(section: TableSection, results_dir: Path, categories: dict[str, str], plot_prefix: str) -> list[LobeFigure]:
    out = []
    for material in chosen_materials(section, categories):
        docs: dict[int, dict] = {}
        missing = []
        for k, row in enumerate(section.rows):
            entry = artifacts.lookup(results_dir, row.config_hash, material).get("lobes")
            doc = lobes.read(Path(results_dir) / entry["path"]) if entry else None
            if doc is not None:
                docs[k] = doc
            elif not row.reference:
                missing.append(row.label)
        shown = [k for k in sorted(docs) if not section.rows[k].reference]
        if not shown:
            continue
        first = docs[min(docs)]
        theta_o = np.radians(np.asarray(first["theta_o_deg"], dtype=float))
        table = _slices(first, "table")
        models = {k: _slices(docs[k], "model") for k in shown}
        curves = table + [c for m in models.values() for c in m]
        finite = [float(np.nanmax(c)) for c in curves if np.isfinite(c).any()]
        top = max(finite + [LOBE_FLOOR])
        decades = max(1, math.ceil(float(_radius(np.array(top)))))
        prefix = f"{plot_prefix}{len(out)}"
        panels = [LobePanel(k, lobe_svg.lobe_panels(first["theta_i_deg"], theta_o, [_radius(t) for t in table],
                                                    {k: [_radius(m) for m in models[k]]}, f"{prefix}-{k}",
                                                    int(math.log10(LOBE_FLOOR)), decades=decades, linear_max=top))
                  for k in shown]
        out.append(LobeFigure(material, [float(t) for t in first["theta_i_deg"]], panels, missing))
    return out


# --------------------------------------------------------------------------- image grids

FLIP_CMAP = "magma"  # the FLIP map, 0 (black) to 1
RELATIVE_CMAP = "inferno"  # the relative error in luminance, 0 to REL_ERROR_MAX
#: The stored per-material figures printed under each render, where the section has them.
IMAGE_FIGURES = ("psnr_ldr", "flip_ldr")


@dataclass(frozen=True)
class ImageCell:
    label: str
    config_hash: str
    image: str | None  # paths relative to the results folder (None: not saved)
    flip: str | None
    relative: str | None
    note: str = ""
    figures: dict[str, float] = field(default_factory=dict)  # metric → this material's stored figure


@dataclass(frozen=True)
class ImageRow:
    material: str
    reference: str | None
    cells: list[ImageCell]
    caption: str


def colour_stops(cmap: str, n: int = 11) -> list[str]:
    """`n` evenly spaced colours of a matplotlib colormap, as #rrggbb: a colour bar's gradient."""
    from matplotlib import colormaps

    rgba = colormaps[cmap](np.linspace(0.0, 1.0, n))
    return ["#" + "".join(f"{int(c * 255 + 0.5):02x}" for c in rgb[:3]) for rgb in rgba]


def per_image(section: TableSection, config_hash: str, material: str) -> dict[str, float]:
    """The stored figures of one configuration's render of one material (`IMAGE_FIGURES`),
    from the section's per-material values."""
    got = {name: section.per_material.get(name, {}).get((config_hash, material)) for name in IMAGE_FIGURES}
    return {name: float(v) for name, v in got.items() if v is not None}


def sampler_text(name: str | None, params: dict | None) -> str:
    if not name:
        return ""
    inner = ", ".join(f"{k}={v:g}" if isinstance(v, (int, float)) else f"{k}={v}" for k, v in sorted((params or {}).items()))
    return f"{name}({inner})" if inner else name


def _caption(meta: dict) -> str:
    """How the images shown were rendered and how the stored metrics were."""
    how = [f"simulator {meta.get('simulator')}"]
    sampler = sampler_text(meta.get("sampler"), meta.get("sampler_params"))
    if meta.get("spp"):
        fitted = " (fitted to the material)" if meta.get("display_sampler") == "fitted" else ""
        how.append(f"shown at {meta['spp']} spp, sampler {sampler}{fitted}")
    if meta.get("measured_spp"):
        how.append(f"metrics measured at {meta['measured_spp']} spp, sampler {meta.get('measured_sampler') or sampler}")
    return ", ".join(how)


def _fresh(target: Path, *sources: Path) -> bool:
    try:
        t = target.stat().st_mtime
        return all(s.stat().st_mtime <= t for s in sources)
    except OSError:
        return False


def _write_map(path: Path, values: np.ndarray, cmap: str, vmax: float) -> None:
    from matplotlib import colormaps
    from PIL import Image

    rgba = colormaps[cmap](np.clip(values / vmax, 0, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    with replacing(path) as tmp:
        Image.fromarray((rgba[..., :3] * 255 + 0.5).astype(np.uint8)).save(tmp, format="PNG")


def error_maps(results_dir: Path, image_exr: Path, reference_exr: Path, stem: str, exposure: float) -> tuple[str, str]:
    """FLIP map (LDR) and relative-error heat map of one render against its reference, as
    PNGs under `<results>/report-images/` (reused while newer than both renders)."""
    import torch

    from brdfbench.images import read_exr  # lazy: torch
    from brdfbench.distances.image_functional import flip  # lazy: torch

    folder = Path(results_dir) / FOLDER
    flip_png, rel_png = folder / f"{stem}.flip.png", folder / f"{stem}.relerr.png"
    if not (_fresh(flip_png, image_exr, reference_exr) and _fresh(rel_png, image_exr, reference_exr)):
        image, reference = read_exr(image_exr), read_exr(reference_exr)
        _, fmap = flip(image, reference, space="ldr", exposure=exposure, return_map=True)
        _write_map(flip_png, fmap.numpy(), FLIP_CMAP, 1.0)
        lum = lambda x: (x.to(torch.float64) @ torch.tensor([0.2126, 0.7152, 0.0722], dtype=torch.float64)).numpy()
        ref = lum(reference)
        rel = np.abs(lum(image) - ref) / np.maximum(ref, 1e-3 * max(float(ref.max()), 1e-12))
        _write_map(rel_png, rel, RELATIVE_CMAP, REL_ERROR_MAX)
    root = Path(results_dir)
    return str(flip_png.relative_to(root)), str(rel_png.relative_to(root))


def _png(results_dir: Path, exr: Path) -> str:
    return str(exr.with_suffix(".png").relative_to(results_dir))


def _cell(section: TableSection, row, material: str, results_dir: Path, entries: dict) -> ImageCell:
    image, ref = entries.get("image"), entries.get("reference")
    figures = per_image(section, row.config_hash, material)
    if not image or not ref:
        return ImageCell(row.label, row.config_hash, None, None, None, "no saved render", figures)
    image_exr, ref_exr = results_dir / image["path"], results_dir / ref["path"]
    if not (image_exr.is_file() and ref_exr.is_file()):
        return ImageCell(row.label, row.config_hash, None, None, None, "render file missing", figures)
    try:
        flip_png, rel_png = error_maps(results_dir, image_exr, ref_exr, f"{row.config_hash}-{artifacts._safe(material)}",
                                       float(image.get("exposure") or 0.0))
    except Exception as exc:  # an unreadable EXR: say so in place of the maps
        return ImageCell(row.label, row.config_hash, _png(results_dir, image_exr), None, None,
                         f"error maps failed: {exc}", figures)
    return ImageCell(row.label, row.config_hash, _png(results_dir, image_exr), flip_png, rel_png, "", figures)


def image_rows(section: TableSection, results_dir: Path, categories: dict[str, str]) -> list[ImageRow]:
    """Per chosen material: the reference render (the table's) and each configuration's
    render with its error maps; the references (the target itself) get no column of their
    own, their render being the reference's."""
    results_dir = Path(results_dir)
    out = []
    for material in chosen_materials(section, categories):
        reference, meta, cells = None, {}, []
        for row in section.rows:
            entries = artifacts.lookup(results_dir, row.config_hash, material)
            image, ref = entries.get("image"), entries.get("reference")
            if image and ref and (results_dir / ref["path"]).is_file():
                meta = meta or image
                reference = reference or _png(results_dir, results_dir / ref["path"])
            if not row.reference:
                cells.append(_cell(section, row, material, results_dir, entries))
        if reference is None or not cells:
            continue
        out.append(ImageRow(material, reference, cells, _caption(meta)))
    return out
