/**
 * Small SVG charts drawn by hand: a line/dot chart with reference lines, and a
 * bar chart. Each chart is an <svg role="img"> whose aria-label states what it
 * shows, with an HTML legend and a one-line text readout below it.
 */

import { fmt, svgEl } from "./svg.js";

const W = 360;
const PAD = { left: 46, right: 10, top: 8, bottom: 22 };

/** About `count` round tick values covering [lo, hi] (whole numbers only when `integer`). */
export function ticks(lo, hi, count = 4, integer = false) {
  if (!(hi > lo)) return [lo];
  const raw = (hi - lo) / count;
  const power = 10 ** Math.floor(Math.log10(raw));
  let step = [1, 2, 2.5, 5, 10].map((m) => m * power).find((s) => s >= raw) || raw;
  if (integer) step = Math.max(1, Math.round(step));
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(Number(v.toPrecision(12)));
  return out;
}

class Chart {
  /** @param {HTMLElement} figure container (a <figure> with a <figcaption>) */
  constructor(figure, { height = 150 } = {}) {
    this.height = height;
    this.svg = svgEl("svg", { viewBox: `0 0 ${W} ${height}`, role: "img", preserveAspectRatio: "xMidYMid meet" });
    this.legend = document.createElement("ul");
    this.legend.className = "legend";
    this.readout = document.createElement("p");
    this.readout.className = "readout";
    figure.append(this.svg, this.legend, this.readout);
  }

  setLegend(items) {
    this.legend.replaceChildren(
      ...items.map(({ name, color, line }) => {
        const li = document.createElement("li");
        const swatch = document.createElement("span");
        swatch.className = line ? "swatch line" : "swatch";
        swatch.style.background = color;
        li.append(swatch, document.createTextNode(name));
        return li;
      }),
    );
  }

  axes(xs, ys, { xTicks = true, yInteger = false } = {}) {
    const plotW = W - PAD.left - PAD.right;
    const plotH = this.height - PAD.top - PAD.bottom;
    const sx = (v) => PAD.left + ((v - xs[0]) / (xs[1] - xs[0] || 1)) * plotW;
    const sy = (v) => PAD.top + plotH - ((v - ys[0]) / (ys[1] - ys[0] || 1)) * plotH;
    for (const t of ticks(ys[0], ys[1], 4, yInteger)) {
      svgEl("line", { class: "grid", x1: PAD.left, x2: W - PAD.right, y1: sy(t), y2: sy(t) }, this.svg);
      const label = svgEl("text", { class: "tick", x: PAD.left - 4, y: sy(t) + 3, "text-anchor": "end" }, this.svg);
      label.textContent = fmt(t, 3);
    }
    for (const t of xTicks ? ticks(xs[0], xs[1], 5, true) : []) {
      const label = svgEl("text", { class: "tick", x: sx(t), y: this.height - 6, "text-anchor": "middle" }, this.svg);
      label.textContent = fmt(t, 4);
    }
    svgEl("line", { class: "axis", x1: PAD.left, x2: PAD.left, y1: PAD.top, y2: PAD.top + plotH }, this.svg);
    svgEl("line", { class: "axis", x1: PAD.left, x2: W - PAD.right, y1: PAD.top + plotH, y2: PAD.top + plotH }, this.svg);
    return { sx, sy };
  }

  noData(text) {
    this.svg.replaceChildren();
    const label = svgEl("text", { class: "nodata", x: W / 2, y: this.height / 2, "text-anchor": "middle" }, this.svg);
    label.textContent = text;
    this.svg.setAttribute("aria-label", text);
    this.svg.dataset.points = "0";
  }
}

export class LineChart extends Chart {
  /**
   * @param {{series: {name: string, color: string, points: number[][], dots?: boolean, colorOf?: (p: any[]) => string}[],
   *          rules?: {name: string, value: number, color: string}[], label: string, empty: string}} spec
   */
  update({ series, rules = [], label, empty }) {
    const drawn = series.filter((s) => s.points.length > 0);
    const total = drawn.reduce((a, s) => a + s.points.length, 0);
    if (total === 0) {
      this.noData(empty);
      this.setLegend([]);
      return;
    }
    this.svg.replaceChildren();
    let [x0, x1, y0, y1] = [Infinity, -Infinity, Infinity, -Infinity];
    for (const s of drawn) {
      for (const [x, y] of s.points) {
        x0 = Math.min(x0, x);
        x1 = Math.max(x1, x);
        y0 = Math.min(y0, y);
        y1 = Math.max(y1, y);
      }
    }
    for (const r of rules) {
      y0 = Math.min(y0, r.value);
      y1 = Math.max(y1, r.value);
    }
    y0 = Math.min(0, y0);
    y1 = y1 > y0 ? y1 * 1.05 : y0 + 1;
    if (x1 === x0) x1 = x0 + 1;
    const { sx, sy } = this.axes([x0, x1], [y0, y1]);
    for (const r of rules) {
      svgEl("line", { class: "rule", x1: sx(x0), x2: sx(x1), y1: sy(r.value), y2: sy(r.value), stroke: r.color, "data-rule": r.name }, this.svg);
    }
    for (const s of drawn) {
      if (s.dots) {
        const group = svgEl("g", { "data-series": s.name }, this.svg);
        for (const p of s.points) {
          svgEl("circle", { cx: sx(p[0]), cy: sy(p[1]), r: 1.8, fill: s.colorOf ? s.colorOf(p) : s.color }, group);
        }
      } else {
        const points = s.points.map(([x, y]) => `${sx(x).toFixed(1)},${sy(y).toFixed(1)}`).join(" ");
        svgEl("polyline", { class: "series", points, stroke: s.color, "data-series": s.name }, this.svg);
        const [lx, ly] = s.points[s.points.length - 1];
        svgEl("circle", { cx: sx(lx), cy: sy(ly), r: 2.5, fill: s.color }, this.svg);
      }
    }
    this.svg.dataset.points = String(total);
    this.svg.setAttribute("aria-label", label);
    this.setLegend([
      ...drawn.filter((s) => !s.hideInLegend).map((s) => ({ name: s.name, color: s.color, line: !s.dots })),
      ...rules.map((r) => ({ name: r.name, color: r.color, line: true })),
    ]);
  }
}

export class BarChart extends Chart {
  /** @param {{bars: {label: string, value: number, color: string}[], label: string, empty: string}} spec */
  update({ bars, label, empty }) {
    if (bars.length === 0) {
      this.noData(empty);
      return;
    }
    this.svg.replaceChildren();
    const top = Math.max(1, ...bars.map((b) => b.value));
    const { sy } = this.axes([0, 1], [0, top * 1.05], { xTicks: false, yInteger: true });
    const plotW = W - PAD.left - PAD.right;
    const slot = plotW / bars.length;
    const width = Math.max(1, slot * 0.75);
    bars.forEach((b, i) => {
      const x = PAD.left + i * slot + (slot - width) / 2;
      const rect = svgEl(
        "rect",
        { x, y: sy(b.value), width, height: sy(0) - sy(b.value), fill: b.color, "data-bar": b.label, "data-value": b.value },
        this.svg,
      );
      const title = svgEl("title", {}, rect);
      title.textContent = `${b.label}: ${b.value}`;
    });
    if (bars.length <= 16) {
      bars.forEach((b, i) => {
        const text = svgEl("text", { class: "tick", x: PAD.left + (i + 0.5) * slot, y: this.height - 6, "text-anchor": "middle" }, this.svg);
        text.textContent = b.label.length > 6 ? `${b.label.slice(0, 5)}…` : b.label;
      });
    }
    this.svg.dataset.points = String(bars.length);
    this.svg.setAttribute("aria-label", label);
  }
}
