"""Small pieces every HTML renderer of the report shares: escaping, sortable numbers, cells
of the view's tables, header cells, inline SVG of a matplotlib figure."""

from __future__ import annotations

import html
import io
from importlib import resources

from . import units
from .units import fmt
from .view import Cell, Metric

CONTENDED = "†"
ON_GPU = "‡"


def esc(text) -> str:
    return html.escape(str(text), quote=True)


def asset(name: str) -> str:
    return resources.files("brdfbench_leaderboard").joinpath("assets", name).read_text(encoding="utf-8")


def assets(suffix: str) -> str:
    """Every stylesheet (".css") or script (".js") of the page, `report.*` first: each part
    of the report keeps its own file, and the page inlines them all."""
    folder = resources.files("brdfbench_leaderboard").joinpath("assets")
    names = sorted((p.name for p in folder.iterdir() if p.name.endswith(suffix)),
                   key=lambda n: (not n.startswith("report."), n))
    return "\n".join(asset(n) for n in names)


def svg(fig, salt: str) -> str:
    """A figure as inline SVG markup; `salt` keeps its internal ids apart from other figures'."""
    import matplotlib

    buf = io.StringIO()
    with matplotlib.rc_context({"svg.hashsalt": salt, "svg.fonttype": "none"}):
        fig.savefig(buf, format="svg")
    text = buf.getvalue()
    return text[text.index("<svg"):]


def number(value: float | None) -> str:
    return "" if value is None else repr(float(value))


def cell(c: Cell | None, metric: Metric, best: bool = False, extra: bool = False, note: str = "") -> str:
    """A table cell of the view: the figure as `metric.show` prints it, the interval (or
    `note`) below, median and worst case in the tooltip (with the exact figure where the
    printed one is in scaled units); `extra`: a column the compact view hides."""
    cls = ["extra"] if extra else []
    if c is None:
        return f'<td class="{" ".join(["missing", *cls])}" data-sort="" title="no figure">–</td>'
    mark = (CONTENDED if metric.timed and c.contended else "") + (ON_GPU if metric.timed and c.accelerator else "")
    detail = f"median {metric.show(c.median)}, worst {metric.show(c.worst)}, {c.n}/{c.expected} materials"
    if c.complete and metric.kind == "cost" and units.scales(metric.unit):
        detail = f"{fmt(c.value)} {metric.unit}; {detail}"
    if metric.timed and c.accelerator:
        detail += f"; measured on a GPU ({c.accelerator})"
    if not c.complete:
        partial = f"partial {metric.aggregate} {metric.show(c.partial)} over {c.n}/{c.expected} materials"
        return (f'<td class="{" ".join(["missing", *cls])}" data-sort="" title="{esc(partial)}">–'
                f'<span class="ci">{c.missing} missing</span></td>')
    below = f"[{fmt(c.lo)}, {fmt(c.hi)}]" if c.lo is not None else note
    ci = f'<span class="ci">{esc(below)}</span>' if below else ""
    if best:
        cls.append("best")
        detail += "; best of the configurations with a figure"
    attr = f' class="{" ".join(cls)}"' if cls else ""
    return (f'<td{attr} data-sort="{number(c.value)}" title="{esc(detail)}">'
            f"{esc(metric.show(c.value) + mark)}{ci}</td>")


def span(text: str) -> str:
    return f'<span class="ci">{esc(text)}</span>' if text else ""


def th(text: str, title: str = "", cls: str = "") -> str:
    attrs = (f' class="{cls}"' if cls else "") + (f' title="{esc(title)}"' if title else "")
    return f"<th{attrs}>{esc(text)}</th>"




def anchor(sid: str, kind: str, material: str) -> str:
    """The id of one material's figure of a kind ("lobe", "render") in section `sid`: the
    per-material heat map links to it."""
    slug = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in material)
    return f"{sid}-{kind}-{slug}"
