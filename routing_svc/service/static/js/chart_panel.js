/**
 * The "Learning" panel: running mean service cost (whole run and the recent
 * window, with the optimum when the fleet has a reference demand), the step
 * size of each update, the number of updates of each vehicle, and the service
 * levels (the fraction of the recent window's targets that the dispatched
 * vehicles completed within each threshold, from the stream's metrics).
 */

import { BarChart, LineChart } from "./charts.js";
import { fmt } from "./svg.js";

const MEAN = "#1d2330";
const RECENT = "#0b84d8";
const EXPECTED = "#8e44ad";
const OPTIMUM = "#1b7f3b";
const LEVELS = ["#1b7f3b", "#e67e22", "#c0392b", "#0b84d8", "#8e44ad"];

export class ChartPanel {
  constructor(root) {
    this.root = root;
    this.empty = root.querySelector("#charts-empty");
    this.cost = new LineChart(root.querySelector("#chart-cost"));
    this.step = new LineChart(root.querySelector("#chart-step"), { height: 120 });
    this.updates = new BarChart(root.querySelector("#chart-updates"), { height: 110 });
    this.levels = new LineChart(root.querySelector("#chart-levels"), { height: 120 });
  }

  render(state, colors) {
    this.root.hidden = false;
    const none = state.targets === 0;
    this.empty.hidden = !none;
    if (none) {
      this.empty.textContent =
        "No targets yet. Post one with the panel above (click “Place on map”, then click the map) " +
        `or with POST /v1/fleets/${state.id}/targets.`;
    }
    this.renderCost(state);
    this.renderStep(state, colors);
    this.renderUpdates(state, colors);
    this.renderLevels(state);
  }

  renderLevels(state) {
    const series = state.thresholds.map((limit, i) => ({
      name: `within ${limit} ${state.unit}`,
      color: LEVELS[i % LEVELS.length],
      points: state.series.levels.map(([n, within]) => [n, within[i]]),
    }));
    const last = state.series.levels[state.series.levels.length - 1];
    const text = last
      ? state.thresholds.map((limit, i) => `≤ ${limit} ${state.unit}: ${fmt(100 * last[1][i], 3)} %`).join(" · ")
      : "";
    this.levels.update({ series, label: `Service levels, recent window; ${text}`, empty: "no targets yet" });
    this.levels.readout.textContent = text;
    this.levels.readout.dataset.within = last ? last[1].join(",") : "";
  }

  renderCost(state) {
    const m = state.metrics;
    const unit = state.unit;
    const optimum = m.optimum;
    const comparable = optimum && state.objective === "routing";
    const rules = comparable ? [{ name: `optimum ${fmt(optimum.objective)} ${unit}`, value: optimum.objective, color: OPTIMUM }] : [];
    const series = [
      { name: `mean, last ${state.window}`, color: RECENT, points: state.series.recent },
      { name: "mean, whole run", color: MEAN, points: state.series.mean },
    ];
    if (comparable) series.push({ name: "expected cost now (exact)", color: EXPECTED, points: state.series.expected });
    const mean = m.version === state.version ? m.mean_cost : state.targets ? state.costSum / state.targets : null;
    const recent = state.recentCosts.length ? state.recentCosts.reduce((a, b) => a + b, 0) / state.recentCosts.length : null;
    let text = `${state.targets} targets · mean ${fmt(mean)} ${unit} · last ${state.window}: ${fmt(recent)} ${unit}`;
    if (optimum) {
      text += ` · optimum ${fmt(optimum.objective)} · now ${fmt(optimum.expected_cost)} (gap ${optimum.gap === null ? "– (an optimum of 0)" : `${fmt(100 * optimum.gap, 3)} %`})`;
      if (!comparable) text += ` [objective ${state.objective}: values of E c(T), not of the cost]`;
    }
    this.cost.update({
      series,
      rules,
      label: `Running mean service cost: ${text}`,
      empty: "no targets yet",
    });
    this.cost.readout.textContent = text;
    this.cost.readout.dataset.mean = mean === null ? "" : String(mean);
  }

  renderStep(state, colors) {
    const sizes = Object.values(state.metrics.step_size || {});
    const lo = sizes.length ? Math.min(...sizes) : null;
    const hi = sizes.length ? Math.max(...sizes) : null;
    const text = sizes.length
      ? `current γ: ${lo === hi ? fmt(lo) : `${fmt(lo)} – ${fmt(hi)}`} (${state.unit} of cost per update)`
      : "";
    this.step.update({
      series: [
        {
          name: "step of the vehicle that moved",
          color: "#555",
          dots: true,
          points: state.series.step,
          colorOf: (p) => colors.get(p[2]) || "#555",
        },
      ],
      label: `Step size of each update; ${text}`,
      empty: "no updates yet",
    });
    this.step.readout.textContent = text;
    if (state.series.step.length) this.step.setLegend(state.types.map((t) => ({ name: `type ${t}`, color: colors.get(t) })));
  }

  renderUpdates(state, colors) {
    const order = new Intl.Collator("en", { numeric: true });
    const bars = [...state.vehicles.values()]
      .sort((a, b) => order.compare(a.id, b.id))
      .map((v) => ({ label: v.id, value: v.updates, color: colors.get(v.type) }));
    const total = bars.reduce((a, b) => a + b.value, 0);
    this.updates.update({ bars, label: `Updates per vehicle, ${total} in all`, empty: "no vehicles" });
    const busiest = bars.reduce((a, b) => (b.value > (a ? a.value : -1) ? b : a), null);
    this.updates.readout.textContent = busiest && total ? `${total} updates · most: ${busiest.label} (${busiest.value})` : "no updates yet";
    this.updates.setLegend(state.types.map((t) => ({ name: `type ${t}`, color: colors.get(t) })));
  }
}
