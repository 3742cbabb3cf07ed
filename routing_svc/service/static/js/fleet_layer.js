/**
 * Draws a FleetState on the map: vehicles at their current positions, filled
 * by status and ringed by type, each tied by a thin line to its reference (a
 * small square: where it waits when idle, what learning moves), the trails of
 * the references, the recent targets with a line to each reference that served
 * them, and the latest target's dispatch: a line to each vehicle sent.
 *
 * Every vehicle is a <circle class="vehicle" data-vehicle=ID data-type=T
 * data-status=S data-x=X data-y=Y data-cx=CX data-cy=CY> whose data-x/data-y
 * are its reference and data-cx/data-cy its current position, in network
 * coordinates, exactly as the API reports them; its reference is a
 * <rect class="reference" data-vehicle=ID> and the tie a <line class="anchor">.
 * Every target is a <g class="target" data-seq data-x data-y data-requires
 * data-served-by data-moved>; a dispatch line is a
 * <line class="dispatch" data-target=SEQ data-vehicle=ID>. The posts (where the
 * available vehicles should wait now, GET .../posts) are
 * <circle class="post" data-post-of=ID data-reference-of=ID data-x data-y>, with a
 * <line class="post-line" data-post-of=ID> from a vehicle that is away from its post.
 */

import { svgEl, withTitle } from "./svg.js";

export const STATUS_COLORS = new Map([
  ["available", "#1b7f3b"],
  ["busy", "#e67e22"],
  ["offline", "#8a8f98"],
]);

export class FleetLayer {
  /** @param {import("./map.js").NetworkMap} map */
  constructor(map) {
    this.map = map;
    this.circles = new Map();
    this.trails = new Map();
    this.colors = new Map();
    this.anchors = new Map();
    this.references = new Map();
  }

  /** Start drawing a new fleet. */
  reset(state, colors) {
    this.map.clearOverlays();
    this.circles.clear();
    this.trails.clear();
    this.anchors.clear();
    this.references.clear();
    this.colors = colors;
    const { trails, vehicles, anchors } = this.map.layers;
    for (const v of state.vehicles.values()) {
      const color = colors.get(v.type);
      this.trails.set(v.id, svgEl("polyline", { class: "trail", "data-trail": v.id, stroke: color }, trails));
      this.anchors.set(v.id, svgEl("line", { class: "anchor", "data-vehicle": v.id, stroke: color }, anchors));
      this.references.set(v.id, svgEl("rect", { class: "reference", "data-vehicle": v.id, fill: color }, anchors));
      const circle = svgEl("circle", { class: "vehicle", "data-vehicle": v.id, "data-type": v.type, stroke: color }, vehicles);
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
      circle.setAttribute("cx", String(v.cx));
      circle.setAttribute("cy", String(-v.cy));
      circle.setAttribute("fill", STATUS_COLORS.get(v.status) || "#1d2330");
      circle.dataset.x = String(v.x);
      circle.dataset.y = String(v.y);
      circle.dataset.cx = String(v.cx);
      circle.dataset.cy = String(v.cy);
      circle.dataset.status = v.status;
      circle.dataset.updates = String(v.updates);
      withTitle(
        circle,
        `${v.id} · type ${v.type} · ${v.status} at (${v.cx.toFixed(1)}, ${v.cy.toFixed(1)}) · ` +
          `reference (${v.x.toFixed(1)}, ${v.y.toFixed(1)}) · ${v.updates} updates`,
      );
      const anchor = this.anchors.get(id);
      anchor.setAttribute("x1", String(v.cx));
      anchor.setAttribute("y1", String(-v.cy));
      anchor.setAttribute("x2", String(v.x));
      anchor.setAttribute("y2", String(-v.y));
      anchor.classList.toggle("away", !v.atReference);
      const reference = this.references.get(id);
      reference.setAttribute("x", String(v.x));
      reference.setAttribute("y", String(-v.y));
      this.trails.get(id).setAttribute("points", v.trail.map(([x, y]) => `${x},${-y}`).join(" "));
    }
    state.dirty.clear();
    for (const [id, circle] of this.circles) circle.classList.toggle("moved", id === state.lastMoved);
    this.renderTargets(state);
    this.renderDispatch(state);
  }

  /** Lines from the newest target to the vehicles it dispatched, at their current positions. */
  renderDispatch(state) {
    const layer = this.map.layers.dispatch;
    layer.replaceChildren();
    const d = state.lastDispatch;
    if (!d) return;
    layer.dataset.status = d.status;
    layer.dataset.target = String(d.seq);
    for (const s of d.sent) {
      const line = svgEl(
        "line",
        { class: "dispatch", x1: d.x, y1: -d.y, x2: s.x, y2: -s.y, "data-target": d.seq, "data-vehicle": s.id },
        layer,
      );
      withTitle(line, `target #${d.seq}: ${s.id} sent (${s.cost.toFixed(1)} ${state.unit})`);
    }
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

  /** The posts answer: a ring at each post, a dashed line from a vehicle still on its way. */
  renderPosts(state, answer) {
    const layer = this.map.layers.posts;
    layer.replaceChildren();
    layer.dataset.version = String(answer.version);
    for (const post of answer.posts) {
      const { x, y } = post.position;
      const vehicle = state.vehicles.get(post.vehicle);
      if (vehicle && post.time > 0) {
        svgEl(
          "line",
          { class: "post-line", x1: vehicle.cx, y1: -vehicle.cy, x2: x, y2: -y, "data-post-of": post.vehicle },
          layer,
        );
      }
      const ring = svgEl(
        "circle",
        {
          class: "post",
          cx: x,
          cy: -y,
          "data-post-of": post.vehicle,
          "data-reference-of": post.reference_of,
          "data-x": x,
          "data-y": y,
        },
        layer,
      );
      const whose = post.reference_of === post.vehicle ? "its own reference" : `${post.reference_of}'s reference`;
      withTitle(ring, `post of ${post.vehicle}: ${whose} · ${post.time.toFixed(1)} ${state.unit} away`);
    }
  }

  /** A dashed ring where a target is being posted, until the answer arrives. */
  showPending(point) {
    return svgEl("circle", { class: "pending", cx: point.x, cy: -point.y }, this.map.layers.pending);
  }
}
