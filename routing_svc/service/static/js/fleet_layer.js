/**
 * Draws a FleetState on the map: vehicles (coloured by type), their trails,
 * and the recent targets with a line to each vehicle that served them.
 *
 * Every vehicle is a <circle class="vehicle" data-vehicle=ID data-type=T
 * data-x=X data-y=Y> whose data-x/data-y are its reference position in network
 * coordinates, exactly as the API reports it; every target is a
 * <g class="target" data-seq data-x data-y data-requires data-served-by data-moved>.
 */

import { svgEl, withTitle } from "./svg.js";

export class FleetLayer {
  /** @param {import("./map.js").NetworkMap} map */
  constructor(map) {
    this.map = map;
    this.circles = new Map();
    this.trails = new Map();
    this.colors = new Map();
  }

  /** Start drawing a new fleet. */
  reset(state, colors) {
    this.map.clearOverlays();
    this.circles.clear();
    this.trails.clear();
    this.colors = colors;
    const { trails, vehicles } = this.map.layers;
    for (const v of state.vehicles.values()) {
      const color = colors.get(v.type);
      this.trails.set(v.id, svgEl("polyline", { class: "trail", "data-trail": v.id, stroke: color }, trails));
      const circle = svgEl("circle", { class: "vehicle", "data-vehicle": v.id, "data-type": v.type, fill: color }, vehicles);
      this.circles.set(v.id, circle);
    }
    this.render(state);
  }

  /** Bring the drawing up to date with the state (only vehicles that changed). */
  render(state) {
    for (const id of state.dirty) {
      const v = state.vehicles.get(id);
      const circle = this.circles.get(id);
      if (!v || !circle) continue;
      circle.setAttribute("cx", String(v.x));
      circle.setAttribute("cy", String(-v.y));
      circle.dataset.x = String(v.x);
      circle.dataset.y = String(v.y);
      circle.dataset.updates = String(v.updates);
      withTitle(circle, `${v.id} · type ${v.type} · ${v.updates} updates · (${v.x.toFixed(1)}, ${v.y.toFixed(1)})`);
      this.trails.get(id).setAttribute("points", v.trail.map(([x, y]) => `${x},${-y}`).join(" "));
    }
    state.dirty.clear();
    for (const [id, circle] of this.circles) circle.classList.toggle("moved", id === state.lastMoved);
    this.renderTargets(state);
  }

  renderTargets(state) {
    const { links, targets } = this.map.layers;
    links.replaceChildren();
    targets.replaceChildren();
    const newest = state.recentTargets.length - 1;
    state.recentTargets.forEach((t, i) => {
      const age = newest - i;
      const opacity = Math.max(0.25, 1 - age / state.recentTargets.length);
      const requires = t.requires && t.requires.length ? t.requires : null;
      for (const link of t.links) {
        const vehicle = state.vehicles.get(link.id);
        svgEl(
          "line",
          {
            class: link.moved ? "link" : "link other",
            x1: t.x,
            y1: -t.y,
            x2: link.x,
            y2: -link.y,
            stroke: vehicle ? this.colors.get(vehicle.type) : "#1d2330",
            "stroke-opacity": opacity,
            "data-target": t.seq,
            "data-vehicle": link.id,
          },
          links,
        );
      }
      const group = svgEl(
        "g",
        {
          class: age === 0 ? "target newest" : "target",
          opacity,
          "data-seq": t.seq,
          "data-x": t.x,
          "data-y": t.y,
          "data-requires": requires ? requires.join(",") : "",
          "data-served-by": t.servedBy.join(","),
          "data-moved": t.moved,
        },
        targets,
      );
      svgEl("circle", { class: "target-mark", cx: t.x, cy: -t.y }, group);
      if (state.heterogeneous && requires) {
        const label = svgEl("text", { class: "target-label", x: t.x, y: -t.y }, group);
        label.textContent = requires.join("+");
      }
      const needs = requires ? `needs ${requires.join("+")}` : "any vehicle";
      withTitle(group, `target #${t.seq} (${needs}) · served by ${t.servedBy.join(", ")} · ${t.moved} moved`);
    });
  }

  /** A dashed ring where a target is being posted, until the answer arrives. */
  showPending(point) {
    return svgEl("circle", { class: "pending", cx: point.x, cy: -point.y }, this.map.layers.pending);
  }
}
