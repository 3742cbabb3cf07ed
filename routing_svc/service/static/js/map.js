/**
 * The road network drawn in SVG from its own coordinates, with pan and zoom.
 *
 * Network coordinates are metres with y pointing up; SVG user units are the
 * same metres with y pointing down, so a point (x, y) is drawn at (x, -y).
 * The view is the SVG viewBox, kept at the element's aspect ratio so that a
 * screen pixel has the same size in both directions. The CSS variable --px
 * (metres per screen pixel) lets markers keep a constant size on screen.
 */

import { svgEl } from "./svg.js";

const ZOOM_STEP = 1.5;
const WHEEL_ZOOM = 1.0015;
const PAN_FRACTION = 0.15;
const CLICK_SLOP_PX = 5;
const MIN_WIDTH_M = 20;

export class NetworkMap {
  /**
   * @param {SVGSVGElement} svg
   * @param {{onClick?: (p: {x: number, y: number}) => void, onCursor?: (p: {x: number, y: number} | null) => void}} handlers
   */
  constructor(svg, handlers = {}) {
    this.svg = svg;
    this.handlers = handlers;
    this.edges = svg.querySelector("#edges");
    this.layers = {
      trails: svg.querySelector("#layer-trails"),
      anchors: svg.querySelector("#layer-anchors"),
      links: svg.querySelector("#layer-links"),
      dispatch: svg.querySelector("#layer-dispatch"),
      posts: svg.querySelector("#layer-posts"),
      targets: svg.querySelector("#layer-targets"),
      vehicles: svg.querySelector("#layer-vehicles"),
      pending: svg.querySelector("#layer-pending"),
    };
    this.bounds = null;
    this.networkId = null;
    this.view = { x: 0, y: -1, w: 1, h: 1 };
    this.drag = null;
    this.listen();
    new ResizeObserver(() => this.keepAspect()).observe(svg);
  }

  /** Draw a network from its summary (bounds) and GeoJSON geometry; fit the view. */
  setNetwork(summary, geometry) {
    const parts = [];
    for (const feature of geometry.features) {
      const coords = feature.geometry.coordinates;
      if (coords.length < 2) continue;
      let d = `M${coords[0][0]} ${-coords[0][1]}`;
      for (let i = 1; i < coords.length; i += 1) d += `L${coords[i][0]} ${-coords[i][1]}`;
      parts.push(d);
    }
    this.edges.setAttribute("d", parts.join(""));
    this.svg.dataset.edges = String(parts.length);
    this.svg.dataset.network = summary.id;
    this.networkId = summary.id;
    const [xmin, ymin, xmax, ymax] = geometry.bbox || summary.bounds;
    this.bounds = { xmin, ymin, xmax, ymax };
    this.fit();
  }

  /** Remove what was drawn on top of the network. */
  clearOverlays() {
    for (const layer of Object.values(this.layers)) layer.replaceChildren();
  }

  // -- view -------------------------------------------------------------------

  size() {
    const rect = this.svg.getBoundingClientRect();
    return { width: Math.max(rect.width, 1), height: Math.max(rect.height, 1) };
  }

  /** Show the whole network with a small margin. */
  fit() {
    if (!this.bounds) return;
    const { xmin, ymin, xmax, ymax } = this.bounds;
    const margin = 0.04 * Math.max(xmax - xmin, ymax - ymin, MIN_WIDTH_M);
    this.setView(xmin - margin, -(ymax + margin), xmax - xmin + 2 * margin, ymax - ymin + 2 * margin);
  }

  /** Set the viewBox to contain the given rectangle (SVG units) at the element's aspect ratio. */
  setView(x, y, w, h) {
    const { width, height } = this.size();
    const aspect = width / height;
    const cx = x + w / 2;
    const cy = y + h / 2;
    let vw = Math.max(w, MIN_WIDTH_M);
    let vh = Math.max(h, MIN_WIDTH_M / aspect);
    if (vw / vh > aspect) vh = vw / aspect;
    else vw = vh * aspect;
    this.view = { x: cx - vw / 2, y: cy - vh / 2, w: vw, h: vh };
    this.applyView();
  }

  keepAspect() {
    const { x, y, w, h } = this.view;
    const { width, height } = this.size();
    const vh = w * (height / width);
    this.view = { x, y: y + (h - vh) / 2, w, h: vh };
    this.applyView();
  }

  applyView() {
    const { x, y, w, h } = this.view;
    this.svg.setAttribute("viewBox", `${x} ${y} ${w} ${h}`);
    const px = w / this.size().width;
    this.svg.style.setProperty("--px", String(px));
  }

  /** Zoom by `factor` (> 1 zooms in) keeping the SVG point `at` fixed on screen. */
  zoomBy(factor, at = null) {
    const { x, y, w, h } = this.view;
    const px = at ? at.x : x + w / 2;
    const py = at ? at.y : y + h / 2;
    const nw = w / factor;
    if (nw < MIN_WIDTH_M && factor > 1) return;
    this.view = { x: px - (px - x) / factor, y: py - (py - y) / factor, w: nw, h: h / factor };
    this.applyView();
  }

  /** Pan by a fraction of the view (positive dx moves the view east, dy north). */
  panBy(dx, dy) {
    this.view.x += dx * this.view.w;
    this.view.y -= dy * this.view.h;
    this.applyView();
  }

  /** The SVG point under a client (screen) position. */
  svgPoint(clientX, clientY) {
    const point = new DOMPoint(clientX, clientY).matrixTransform(this.svg.getScreenCTM().inverse());
    return { x: point.x, y: point.y };
  }

  /** Network coordinates (y up) of a client position. */
  toNetwork(clientX, clientY) {
    const p = this.svgPoint(clientX, clientY);
    return { x: p.x, y: -p.y };
  }

  /** Network coordinates of the centre of the view. */
  centre() {
    return { x: this.view.x + this.view.w / 2, y: -(this.view.y + this.view.h / 2) };
  }

  // -- input ------------------------------------------------------------------

  listen() {
    const svg = this.svg;
    svg.addEventListener(
      "wheel",
      (event) => {
        event.preventDefault();
        const factor = WHEEL_ZOOM ** -event.deltaY;
        this.zoomBy(factor, this.svgPoint(event.clientX, event.clientY));
      },
      { passive: false },
    );
    svg.addEventListener("pointerdown", (event) => {
      if (event.button !== 0) return;
      this.drag = { id: event.pointerId, sx: event.clientX, sy: event.clientY, view: { ...this.view }, moved: false };
      svg.setPointerCapture(event.pointerId);
    });
    svg.addEventListener("pointermove", (event) => {
      if (this.handlers.onCursor) this.handlers.onCursor(this.toNetwork(event.clientX, event.clientY));
      const drag = this.drag;
      if (!drag || drag.id !== event.pointerId) return;
      const dx = event.clientX - drag.sx;
      const dy = event.clientY - drag.sy;
      if (!drag.moved && Math.hypot(dx, dy) < CLICK_SLOP_PX) return;
      drag.moved = true;
      svg.classList.add("dragging");
      const px = drag.view.w / this.size().width;
      this.view = { ...drag.view, x: drag.view.x - dx * px, y: drag.view.y - dy * px };
      this.applyView();
    });
    const finish = (event, cancelled) => {
      const drag = this.drag;
      if (!drag || drag.id !== event.pointerId) return;
      this.drag = null;
      svg.classList.remove("dragging");
      if (!cancelled && !drag.moved && this.handlers.onClick) {
        this.handlers.onClick(this.toNetwork(event.clientX, event.clientY));
      }
    };
    svg.addEventListener("pointerup", (event) => finish(event, false));
    svg.addEventListener("pointercancel", (event) => finish(event, true));
    svg.addEventListener("pointerleave", () => this.handlers.onCursor && this.handlers.onCursor(null));
    svg.addEventListener("keydown", (event) => this.onKey(event));
  }

  onKey(event) {
    if (event.altKey || event.ctrlKey || event.metaKey) return;
    const actions = {
      "+": () => this.zoomBy(ZOOM_STEP),
      "=": () => this.zoomBy(ZOOM_STEP),
      "-": () => this.zoomBy(1 / ZOOM_STEP),
      _: () => this.zoomBy(1 / ZOOM_STEP),
      0: () => this.fit(),
      Home: () => this.fit(),
      ArrowLeft: () => this.panBy(-PAN_FRACTION, 0),
      ArrowRight: () => this.panBy(PAN_FRACTION, 0),
      ArrowUp: () => this.panBy(0, PAN_FRACTION),
      ArrowDown: () => this.panBy(0, -PAN_FRACTION),
    };
    const action = actions[event.key];
    if (!action) return;
    event.preventDefault();
    action();
  }
}
