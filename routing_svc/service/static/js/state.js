/**
 * What the dashboard knows about one fleet, advanced by the fleet's events.
 *
 * It starts from the fleet's metrics at version V (targets, mean cost, update
 * counts), the fleet itself (vehicles and their reference positions) and the
 * events up to V (recent history: trails, targets, the running means, which
 * are reconstructed backwards from the mean at V). Events after V then arrive
 * live and are applied in order. Applying a target event sets the vehicles the
 * backward probe moved to their `backed_off` positions and the moved vehicle to
 * the event's `new_position`, so seeing an event twice is harmless.
 *
 * Each vehicle has two places: its reference (x, y), what learning moves, and
 * its current position (cx, cy) with its status, set by `vehicle_state` events
 * (a vehicle at its reference follows it). The latest target's dispatch answer
 * (who was sent from where) is kept for drawing, and the service levels of
 * every metrics message make a series.
 */

export const TRAIL_POINTS = 40;
export const RECENT_TARGETS = 15;
export const SERIES_POINTS = 5000;

function push(list, item, limit) {
  list.push(item);
  if (list.length > limit) list.splice(0, list.length - limit);
}

export class FleetState {
  /**
   * @param {object} fleet `GET /v1/fleets/{id}`
   * @param {object} metrics `GET /v1/fleets/{id}/metrics`, read before `fleet`
   */
  constructor(fleet, metrics) {
    this.id = fleet.id;
    this.network = fleet.network;
    this.cost = fleet.cost;
    this.objective = fleet.objective;
    this.referenceDemand = fleet.reference_demand || null;
    this.vehicles = new Map();
    for (const v of fleet.vehicles) {
      this.vehicles.set(v.id, {
        id: v.id,
        type: v.type,
        speed: v.speed,
        x: v.position.x,
        y: v.position.y,
        status: v.status ?? "available",
        cx: (v.current ?? v.position).x,
        cy: (v.current ?? v.position).y,
        atReference: v.at_reference ?? true,
        updates: metrics.updates[v.id] ?? v.updates,
        trail: [],
      });
    }
    this.types = [...new Set(fleet.vehicles.map((v) => v.type))].sort();
    this.version = metrics.version;
    this.targets = metrics.targets;
    this.costSum = (metrics.mean_cost ?? 0) * metrics.targets;
    this.window = metrics.recent_window;
    this.recentCosts = [];
    this.recentTargets = [];
    this.series = { mean: [], recent: [], step: [], expected: [], levels: [] };
    this.thresholds = fleet.service_thresholds || [];
    this.lastDispatch = null;
    this.metrics = metrics;
    this.lastMoved = null;
    this.deleted = false;
    this.dirty = new Set(this.vehicles.keys());
    this.noteExpected(metrics);
    this.noteLevels(metrics);
  }

  get unit() {
    return this.cost === "time" ? "s" : "m";
  }

  get heterogeneous() {
    return this.types.length > 1;
  }

  /**
   * Rebuild the recent past from the events up to the metrics' version.
   * @param {object[]} events the last events with seq <= this.version, in order
   */
  loadHistory(events) {
    const targets = events.filter((e) => e.kind === "target" && e.result && e.seq <= this.version);
    const costs = targets.map((e) => e.result.cost);
    const n0 = this.targets - targets.length; // targets before the first one we see
    // Prefix sums of what we see, anchored at the known total at version V.
    const seen = costs.reduce((a, b) => a + b, 0);
    let before = this.costSum - seen; // cost sum of the n0 unseen targets
    const window = [];
    targets.forEach((event, i) => {
      const r = event.result;
      const n = n0 + i + 1;
      before += r.cost;
      push(this.series.mean, [n, before / n], SERIES_POINTS);
      window.push(r.cost);
      if (window.length > this.window) window.shift();
      if (window.length === Math.min(this.window, n)) {
        push(this.series.recent, [n, window.reduce((a, b) => a + b, 0) / window.length], SERIES_POINTS);
      }
      for (const back of r.backed_off || []) {
        const vehicle = this.vehicles.get(back.vehicle);
        if (vehicle) this.addTrailPoint(vehicle, back.position.x, back.position.y);
      }
      const mover = this.vehicles.get(r.moved);
      if (mover) {
        push(this.series.step, [n, r.step_size, mover.type], SERIES_POINTS);
        this.addTrailPoint(mover, r.new_position.x, r.new_position.y);
      }
      this.rememberTarget(event.seq, r);
      this.rememberDispatch(event.seq, r);
    });
    this.recentCosts = window;
    for (const v of this.vehicles.values()) this.addTrailPoint(v, v.x, v.y);
    this.dirty = new Set(this.vehicles.keys());
  }

  addTrailPoint(vehicle, x, y) {
    const last = vehicle.trail[vehicle.trail.length - 1];
    if (last && last[0] === x && last[1] === y) return;
    push(vehicle.trail, [x, y], TRAIL_POINTS);
  }

  /** Keep a target with a line to each vehicle that served it (where that vehicle is now). */
  rememberTarget(seq, r) {
    const links = [];
    for (const id of r.served_by) {
      const v = this.vehicles.get(id);
      if (id === r.moved) links.push({ id, x: r.new_position.x, y: r.new_position.y, moved: true });
      else if (v) links.push({ id, x: v.x, y: v.y, moved: false });
    }
    push(
      this.recentTargets,
      {
        seq,
        x: r.target.x,
        y: r.target.y,
        requires: r.requires,
        servedBy: r.served_by,
        moved: r.moved,
        cost: r.cost,
        movedBy: r.moved_by,
        links,
      },
      RECENT_TARGETS,
    );
  }

  /**
   * Apply one event of the log (`event: log` of the stream).
   * @returns {boolean} whether it changed anything
   */
  applyEvent(event) {
    if (event.seq <= this.version) return false;
    this.version = event.seq;
    if (event.kind === "fleet_deleted") {
      this.deleted = true;
      return true;
    }
    if (event.kind === "vehicle_state" && event.result) {
      for (const changed of event.result.vehicles) this.applyVehicleState(changed);
      return true;
    }
    if (event.kind !== "target" || !event.result) return true;
    const r = event.result;
    this.targets += 1;
    this.costSum += r.cost;
    this.recentCosts.push(r.cost);
    if (this.recentCosts.length > this.window) this.recentCosts.shift();
    const n = this.targets;
    push(this.series.mean, [n, this.costSum / n], SERIES_POINTS);
    const recentMean = this.recentCosts.reduce((a, b) => a + b, 0) / this.recentCosts.length;
    if (this.recentCosts.length === Math.min(this.window, n)) push(this.series.recent, [n, recentMean], SERIES_POINTS);
    for (const back of r.backed_off || []) {
      const vehicle = this.vehicles.get(back.vehicle);
      if (!vehicle) continue;
      vehicle.x = back.position.x;
      vehicle.y = back.position.y;
      this.addTrailPoint(vehicle, vehicle.x, vehicle.y);
      this.dirty.add(vehicle.id);
    }
    const mover = this.vehicles.get(r.moved);
    if (mover) {
      mover.x = r.new_position.x;
      mover.y = r.new_position.y;
      mover.updates += 1;
      if (mover.atReference) {
        mover.cx = mover.x;
        mover.cy = mover.y;
      }
      this.addTrailPoint(mover, mover.x, mover.y);
      this.dirty.add(mover.id);
      push(this.series.step, [n, r.step_size, mover.type], SERIES_POINTS);
    }
    this.lastMoved = r.moved;
    this.rememberTarget(event.seq, r);
    this.rememberDispatch(event.seq, r);
    return true;
  }

  /** A vehicle as a `vehicle_state` event's result shows it. */
  applyVehicleState(changed) {
    const v = this.vehicles.get(changed.id);
    if (!v) return;
    v.status = changed.status;
    v.cx = changed.current.x;
    v.cy = changed.current.y;
    v.atReference = changed.at_reference;
    this.dirty.add(v.id);
  }

  /** Keep the dispatch answer of the newest target: lines from it to the vehicles sent. */
  rememberDispatch(seq, r) {
    if (!r.dispatch) return;
    const sent = r.dispatch.vehicles.map((s) => {
      const v = this.vehicles.get(s.vehicle);
      return { id: s.vehicle, x: v ? v.cx : r.target.x, y: v ? v.cy : r.target.y, cost: s.cost };
    });
    this.lastDispatch = { seq, x: r.target.x, y: r.target.y, status: r.dispatch.status, sent };
  }

  /** One point of the service-level series: the recent window's fraction within each threshold. */
  noteLevels(metrics) {
    const levels = metrics.service_levels;
    if (!levels || !levels.recent.targets) return;
    this.thresholds = levels.thresholds;
    const last = this.series.levels[this.series.levels.length - 1];
    if (last && last[0] === metrics.targets) return;
    push(this.series.levels, [metrics.targets, levels.recent.within], SERIES_POINTS);
  }

  /** Apply an `event: metrics` message (authoritative counts when it is current). */
  applyMetrics(metrics) {
    this.metrics = metrics;
    if (metrics.version === this.version) {
      this.targets = metrics.targets;
      this.costSum = (metrics.mean_cost ?? 0) * metrics.targets;
      for (const [id, count] of Object.entries(metrics.updates)) {
        const v = this.vehicles.get(id);
        if (v && v.updates !== count) {
          v.updates = count;
          this.dirty.add(id);
        }
      }
    }
    this.noteExpected(metrics);
    this.noteLevels(metrics);
  }

  noteExpected(metrics) {
    const optimum = metrics.optimum;
    if (!optimum || optimum.expected_cost === null || optimum.expected_cost === undefined) return;
    const last = this.series.expected[this.series.expected.length - 1];
    if (last && last[0] === metrics.targets) return;
    push(this.series.expected, [metrics.targets, optimum.expected_cost], SERIES_POINTS);
  }
}
