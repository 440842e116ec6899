// brdfbench report: the accuracy-against-cost panels, drawn from the JSON beside each plot
// (chart_html.payload) and drawn again when a legend box is toggled or the page's width
// changes: the axes fit the series shown and the Pareto front is recomputed among them.
// Labels go where they collide with no other label (else the point's tooltip names it).
// No dependencies, no network.
(function () {
  "use strict";
  var NS = "http://www.w3.org/2000/svg";
  var FONT = 12, TITLE = 13, R = 4.5, ASPECT = 0.62, MIN_H = 260;

  function node(name, attrs, parent, text) {
    var e = document.createElementNS(NS, name);
    Object.keys(attrs).forEach(function (k) { e.setAttribute(k, attrs[k]); });
    if (text !== undefined) e.textContent = text;
    if (parent) parent.appendChild(e);
    return e;
  }

  // The limits of svg_plot.log_range and svg_plot.linear_range.
  function logRange(values) {
    var lo = Math.min.apply(null, values), hi = Math.max.apply(null, values);
    if (hi / lo < 10) {
      var mid = Math.sqrt(lo * hi);
      lo = Math.min(lo, mid / Math.sqrt(10));
      hi = Math.max(hi, mid * Math.sqrt(10));
    }
    var pad = (Math.log10(hi) - Math.log10(lo)) * 0.1;
    return [Math.pow(10, Math.log10(lo) - pad), Math.pow(10, Math.log10(hi) + pad)];
  }
  function linearRange(values) {
    var lo = Math.min.apply(null, values), hi = Math.max.apply(null, values);
    if (hi - lo <= 1e-12 * Math.max(1, Math.abs(hi))) {
      var half = Math.abs(hi) * 0.05 || 1;
      lo -= half;
      hi += half;
    }
    var pad = (hi - lo) * 0.1;
    return [lo - pad, hi + pad];
  }

  // The front of pareto.pareto_front / pareto.front: sorted from the best x (stable), each
  // point kept that betters the last kept one's y; GPU timings only where no CPU one is shown.
  function paretoFront(points, xUp, yUp) {
    var ordered = points.slice().sort(function (a, b) {
      var dx = xUp ? b.x - a.x : a.x - b.x;
      return dx !== 0 ? dx : (yUp ? b.y - a.y : a.y - b.y);
    });
    var out = [];
    ordered.forEach(function (p) {
      if (!out.length || (yUp ? p.y > out[out.length - 1].y : p.y < out[out.length - 1].y)) out.push(p);
    });
    return out;
  }
  function front(points, xUp, yUp) {
    var cpu = points.filter(function (p) { return !p.gpu; });
    return paretoFront(cpu.length ? cpu : points, xUp, yUp);
  }

  // Ticks: a log axis's candidates (value, label, level) inside its limits, the decades
  // alone where three or more fall inside; a linear axis's round steps (svg_plot.linear_ticks).
  function logTicks(candidates, lo, hi) {
    var inside = candidates.filter(function (c) { return c[0] >= lo * (1 - 1e-9) && c[0] <= hi * (1 + 1e-9); });
    var decades = inside.filter(function (c) { return c[2] === 0; });
    return (decades.length >= 3 ? decades : inside).map(function (c) { return [c[0], c[1]]; });
  }
  function linearTicks(lo, hi, most) {
    var raw = (hi - lo) / Math.max(1, most);
    var base = Math.pow(10, Math.floor(Math.log10(raw)));
    var step = [1, 2, 5, 10].map(function (m) { return m * base; }).filter(function (s) { return s >= raw; })[0];
    var decimals = Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
    var out = [];
    for (var i = Math.ceil(lo / step - 1e-9); i <= Math.floor(hi / step + 1e-9); i++) {
      var v = i * step, text = Math.abs(v).toFixed(decimals);
      out.push([v, (v < 0 && Number(text) !== 0 ? "\u2212" : "") + text]);
    }
    return out;
  }
  // Every n-th tick, for the smallest n that keeps neighbouring labels `gap` apart.
  function thin(ticks, pos, extent, gap) {
    for (var n = 1; n <= ticks.length; n++) {
      var kept = ticks.filter(function (_, i) { return i % n === 0; }), fits = true;
      for (var i = 1; i < kept.length && fits; i++) {
        fits = Math.abs(pos(kept[i][0]) - pos(kept[i - 1][0])) >= (extent(kept[i]) + extent(kept[i - 1])) / 2 + gap;
      }
      if (fits) return kept;
    }
    return ticks.slice(0, 1);
  }

  function scale(limits, log, a, b) {
    var f = log ? Math.log10 : function (v) { return v; };
    var l0 = f(limits[0]), l1 = f(limits[1]);
    return function (v) { return a + (f(v) - l0) / (l1 - l0) * (b - a); };
  }

  // Text metrics in one drawn SVG: width of a string, and the font's box about its baseline.
  function meter(svg) {
    var cache = {};
    var probe = node("text", {"font-size": FONT, x: 0, y: 0, visibility: "hidden"}, svg, "Hg");
    var box = probe.getBBox();
    var m = {ascent: -box.y, height: box.height, width: function (text, size) {
      var key = (size || FONT) + "|" + text;
      if (!(key in cache)) {
        probe.setAttribute("font-size", size || FONT);
        probe.textContent = text;
        cache[key] = probe.getComputedTextLength();
      }
      return cache[key];
    }};
    m.done = function () { svg.removeChild(probe); };
    return m;
  }

  function overlaps(a, b) {
    return a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1;
  }

  // Labels by first fit: front points first, then the rest in series order; eight places
  // round the point, then eight further out with a leader line; first clear of every marker
  // and error bar, then of markers, then of its own marker only, and always of every other
  // label; a label that fits nowhere is left to the point's tooltip.
  function placeLabels(shown, onFront, px, py, box, m) {
    var markers = [], bars = [];
    shown.forEach(function (p) {
      var x = px(p.x), y = py(p.y);
      markers.push({x0: x - R - 1, x1: x + R + 1, y0: y - R - 1, y1: y + R + 1, p: p});
      if (p.lo !== null && p.hi !== null) {
        var a = py(p.lo), b = py(p.hi);
        bars.push({x0: x - 4, x1: x + 4, y0: Math.min(a, b), y1: Math.max(a, b), p: p});
      }
    });
    var placed = [], h = m.height + 2;
    var order = shown.slice().sort(function (a, b) { return (onFront(b) - onFront(a)) || (a.s - b.s); });
    order.forEach(function (p) {
      var w = m.width(p.label) + 2, x = px(p.x), y = py(p.y), spots = [];
      [R + 3, R + 16].forEach(function (d, ring) {
        var e = d * 0.7;
        [[x + d, y - h / 2], [x - d - w, y - h / 2], [x - w / 2, y - d - h], [x - w / 2, y + d],
         [x + e, y - e - h], [x + e, y + e], [x - e - w, y - e - h], [x - e - w, y + e]].forEach(function (c) {
          spots.push({x0: c[0], x1: c[0] + w, y0: c[1], y1: c[1] + h, leader: ring === 1});
        });
      });
      var mine = markers.filter(function (k) { return k.p === p; });
      var passes = [markers.concat(bars), markers, mine];
      var spot = null;
      passes.forEach(function (obstacles) {
        spots.forEach(function (s) {
          if (spot || s.x0 < box.x0 || s.x1 > box.x1 || s.y0 < box.y0 || s.y1 > box.y1) return;
          var clear = function (o) { return !overlaps(s, o); };
          if (placed.every(clear) && obstacles.every(clear)) spot = s;
        });
      });
      if (spot) {
        spot.p = p;
        spot.ax = x;
        spot.ay = y;
        placed.push(spot);
      }
    });
    return placed;
  }

  function staircase(points, px, py) {
    var d = "M" + px(points[0].x).toFixed(1) + "," + py(points[0].y).toFixed(1);
    for (var i = 1; i < points.length; i++) {
      d += " L" + px(points[i].x).toFixed(1) + "," + py(points[i - 1].y).toFixed(1) +
           " L" + px(points[i].x).toFixed(1) + "," + py(points[i].y).toFixed(1);
    }
    return d;
  }

  // Split a title at its comma where it is longer than `room` (the y axis's direction goes below).
  function lines(text, room, m) {
    var at = text.lastIndexOf(", ");
    return m.width(text) <= room || at < 0 ? [text] : [text.slice(0, at), text.slice(at + 2)];
  }

  function drawPanel(host, chart, panel, hidden, colours) {
    var id = chart.id, width = Math.floor(host.clientWidth);
    host.textContent = "";
    if (width < 50) return;
    var height = Math.max(MIN_H, Math.round(width * ASPECT));
    var svg = node("svg", {width: width, height: height, viewBox: "0 0 " + width + " " + height,
                           "font-family": "sans-serif", role: "img", "data-cost": panel.cost}, host);
    var m = meter(svg);
    var shown = panel.points.filter(function (p) { return !hidden[p.s]; });
    var basis = shown.length ? shown : panel.points;
    var ys = [];
    basis.forEach(function (p) { ys.push(p.y); if (p.lo !== null && p.hi !== null) ys.push(p.lo, p.hi); });
    var xl = logRange(basis.map(function (p) { return p.x; }));
    var yl = chart.yLog ? logRange(ys) : linearRange(ys);
    svg.setAttribute("data-xlim", xl.join(" "));
    svg.setAttribute("data-ylim", yl.join(" "));

    var top = TITLE + 16, bottom = 2 * m.height + 14, right = 16;
    var plotH = height - top - bottom;
    var py = scale(yl, chart.yLog, top + plotH, top);
    var yTicks = chart.yLog ? logTicks(panel.yTicks, yl[0], yl[1]) : linearTicks(yl[0], yl[1], Math.floor(plotH / 40));
    yTicks = thin(yTicks, py, function () { return m.height; }, 6);
    var yTitle = lines(chart.yTitle, plotH, m);
    var tickW = Math.max.apply(null, [0].concat(yTicks.map(function (t) { return m.width(t[1]); })));
    var left = 6 + yTitle.length * m.height + 6 + tickW + 6;
    var px = scale(xl, true, left, width - right);
    var xTicks = logTicks(panel.xTicks, xl[0], xl[1]).filter(function (t) {
      var half = m.width(t[1]) / 2;
      return px(t[0]) - half >= left - 6 && px(t[0]) + half <= width;  // clear of the y ticks' labels
    });
    xTicks = thin(xTicks, px, function (t) { return m.width(t[1]); }, 12);

    var grid = [];
    xTicks.forEach(function (t) { grid.push("M" + px(t[0]).toFixed(1) + "," + top + " V" + (top + plotH)); });
    yTicks.forEach(function (t) { grid.push("M" + left + "," + py(t[0]).toFixed(1) + " H" + (width - right)); });
    node("path", {d: grid.join(" "), stroke: "#e1e4ea", "stroke-width": 1, fill: "none"}, svg);
    node("rect", {x: left, y: top, width: width - right - left, height: plotH, fill: "none", stroke: "#333333",
                  "stroke-width": 0.8}, svg);
    xTicks.forEach(function (t) {
      node("text", {"class": "tick-x", x: px(t[0]).toFixed(1), y: top + plotH + 4 + m.ascent, "font-size": FONT,
                    "text-anchor": "middle", "data-value": t[0]}, svg, t[1]);
    });
    yTicks.forEach(function (t) {
      node("text", {"class": "tick-y", x: left - 6, y: (py(t[0]) - m.height / 2 + m.ascent).toFixed(1),
                    "font-size": FONT, "text-anchor": "end", "data-value": t[0]}, svg, t[1]);
    });
    node("text", {"class": "axis-title", x: (left + width - right) / 2, y: height - 6 - m.height + m.ascent,
                  "font-size": FONT, "text-anchor": "middle"}, svg, panel.xTitle);
    var cy = top + plotH / 2;
    yTitle.forEach(function (line, i) {
      var x = 6 + i * m.height + m.ascent;
      node("text", {"class": "axis-title", x: x, y: cy, "font-size": FONT, "text-anchor": "middle",
                    transform: "rotate(-90 " + x + " " + cy + ")"}, svg, line);
    });
    node("text", {"class": "panel-title", x: (left + width - right) / 2, y: TITLE + 4, "font-size": TITLE,
                  "font-weight": 600, "text-anchor": "middle"}, svg, panel.title);

    var best = front(shown, panel.xUp, chart.yUp);
    var onFront = function (p) { return best.indexOf(p) >= 0 ? 1 : 0; };
    (panel.curves || []).forEach(function (curve) {
      var pts = curve.points.map(function (i) { return panel.points[i]; }).filter(function (p) { return !hidden[p.s]; });
      if (pts.length < 2) return;
      node("path", {id: id + "-size-" + curve.name, "class": "size-curve", fill: "none", stroke: colours(pts[0].s),
                    "stroke-width": 1, opacity: 0.6,
                    d: pts.map(function (p, i) { return (i ? "L" : "M") + px(p.x).toFixed(1) + "," + py(p.y).toFixed(1); }).join(" ")}, svg);
    });
    node("path", {id: id + "-front-" + panel.cost, "class": "front", fill: "none", stroke: "#595959",
                  "stroke-width": 1.2, "stroke-dasharray": "5,3",
                  "data-front": best.map(function (p) { return p.s; }).join(" "),
                  d: best.length ? staircase(best, px, py) : ""}, svg);

    var groups = {};
    panel.points.forEach(function (p) {
      var colour = colours(p.s), x = px(p.x), y = py(p.y);
      var g = node("g", {id: id + "-s" + p.s + "-" + panel.cost, "data-series": p.s}, svg);
      if (hidden[p.s]) g.style.display = "none";
      node("title", {}, g, p.tip);
      if (p.lo !== null && p.hi !== null) {
        var lo = py(p.lo).toFixed(1), hi = py(p.hi).toFixed(1);
        node("path", {stroke: colour, "stroke-width": 1.2, fill: "none",
                      d: "M" + x + "," + lo + " V" + hi + " M" + (x - 3) + "," + lo + " h6 M" + (x - 3) + "," + hi + " h6"}, g);
      }
      var edge = onFront(p) ? "#ffffff" : colour;
      if (p.ref) {
        node("rect", {"class": "marker", x: x - R, y: y - R, width: 2 * R, height: 2 * R, fill: colour, stroke: edge}, g);
      } else {
        node("circle", {"class": "marker", cx: x, cy: y, r: R, fill: colour, stroke: edge}, g);
      }
      groups[p.s] = g;
    });
    var box = {x0: left + 2, x1: width - right - 2, y0: top + 2, y1: top + plotH - 2};
    placeLabels(shown, onFront, px, py, box, m).forEach(function (s) {
      var g = groups[s.p.s];
      if (s.leader) {
        var tx = Math.max(s.x0, Math.min(s.ax, s.x1)), ty = Math.max(s.y0, Math.min(s.ay, s.y1));
        node("path", {"class": "leader", d: "M" + s.ax + "," + s.ay + " L" + tx + "," + ty, stroke: colours(s.p.s),
                      "stroke-width": 0.8, fill: "none"}, g);
      }
      node("text", {"class": "label", x: (s.x0 + 1).toFixed(1), y: (s.y0 + 1 + m.ascent).toFixed(1),
                    "font-size": FONT, fill: colours(s.p.s), stroke: "#ffffff", "stroke-width": 3,
                    "paint-order": "stroke"}, g, s.p.label);
    });
    m.done();
  }

  function setUp(script) {
    var chart = JSON.parse(script.textContent);
    var container = document.getElementById(chart.id);
    var legend = document.querySelector('.legend[data-chart="' + chart.id + '"]');
    if (!container) return;
    var boxes = legend ? Array.prototype.slice.call(legend.querySelectorAll("input[data-series]")) : [];
    var colours = function (k) { return chart.colours[k] || "#333333"; };
    container.textContent = "";
    container.classList.add("drawn");
    var hosts = chart.panels.map(function () {
      var host = document.createElement("div");
      host.className = "cost-panel";
      return container.appendChild(host);
    });
    var width = -1;
    function draw() {
      var hidden = {};
      boxes.forEach(function (b) {
        var k = /-s(\d+)-$/.exec(b.getAttribute("data-series"));
        if (k && !b.checked) hidden[Number(k[1])] = true;
      });
      width = container.clientWidth;
      chart.panels.forEach(function (panel, j) { drawPanel(hosts[j], chart, panel, hidden, colours); });
    }
    boxes.forEach(function (b) { b.addEventListener("change", draw); });
    draw();
    var again = function () { if (container.clientWidth !== width) draw(); };
    if (window.ResizeObserver) new ResizeObserver(again).observe(container);
    else window.addEventListener("resize", again);
  }

  document.querySelectorAll('script[type="application/json"][data-cost-chart]').forEach(setUp);
})();
