/**
 * The dashboard page: picks a fleet, loads its recent past through the REST
 * API, then follows it live through the fleet's event stream.
 *
 * For tests and scripts the <body> carries data-state ("loading", "ready",
 * "empty", "error"), data-fleet (the chosen fleet) and data-version (the last
 * event applied to the page).
 */

import { Api } from "./api.js";
import { ChartPanel } from "./chart_panel.js";
import { FleetLayer } from "./fleet_layer.js";
import { LiveFeed } from "./live.js";
import { NetworkMap } from "./map.js";
import { FleetState } from "./state.js";
import { fmt, typeColors } from "./svg.js";
import { TargetPanel } from "./target_panel.js";

const HISTORY_EVENTS = 1000;
const RECENT_ROWS = 10;
const CHART_INTERVAL_MS = 300;
const FLEET_POLL_EMPTY_MS = 3000;
const FLEET_POLL_MS = 30000;
const POSTS_DELAY_MS = 500;

const $ = (selector) => document.querySelector(selector);
const body = document.body;
const api = new Api(body.dataset.base || "");

const ui = {
  select: $("#fleet-select"),
  summary: $("#fleet-summary"),
  message: $("#map-message"),
  legend: $("#legend"),
  cursor: $("#cursor"),
  noFleets: $("#no-fleets"),
  noFleetsExample: $("#no-fleets-example"),
  recent: $("#recent"),
  recentEmpty: $("#recent-empty"),
  recentRows: $("#recent-table tbody"),
};

let panel = null;
const map = new NetworkMap($("#map"), {
  onClick: (point) => panel && panel.onMapClick(point),
  onCursor: (point) => {
    ui.cursor.textContent = point ? `x ${point.x.toFixed(1)} · y ${point.y.toFixed(1)}` : "";
  },
});
const layer = new FleetLayer(map);
panel = new TargetPanel($("#post-panel"), { api, map, layer });
const charts = new ChartPanel($("#charts"));
const live = new LiveFeed($("#live-status"));

const page = {
  networks: [],
  fleets: [],
  geometry: new Map(),
  state: null,
  colors: new Map(),
  token: 0,
  frame: 0,
  chartsDrawnAt: 0,
  chartTimer: 0,
  fleetTimer: 0,
  postsTimer: 0,
};

// -- messages -------------------------------------------------------------------

function showMessage(text, { alert = false } = {}) {
  ui.message.hidden = !text;
  ui.message.textContent = text || "";
  if (alert) ui.message.setAttribute("role", "alert");
  else ui.message.removeAttribute("role");
}

// -- fleets list --------------------------------------------------------------

/** List the fleets; a shown fleet that is no longer listed stays, marked deleted. */
function fillFleetSelect(fleets, shown) {
  ui.select.replaceChildren();
  if (fleets.length === 0 && !shown) {
    ui.select.append(new Option("no fleets yet", ""));
    ui.select.disabled = true;
    return;
  }
  for (const fleet of fleets) {
    ui.select.append(new Option(`${fleet.id} (${fleet.vehicles.length} vehicles)`, fleet.id));
  }
  if (shown && !fleets.some((f) => f.id === shown)) {
    const gone = new Option(`${shown} (deleted)`, shown);
    gone.disabled = true;
    ui.select.prepend(gone);
  }
  ui.select.disabled = false;
  if (shown) ui.select.value = shown;
}

async function refreshFleets() {
  clearTimeout(page.fleetTimer);
  try {
    const { items } = await api.fleets();
    const before = page.fleets.map((f) => f.id).join("\n");
    page.fleets = items;
    if (items.map((f) => f.id).join("\n") !== before) {
      const shown = page.state ? page.state.id : null;
      fillFleetSelect(items, shown);
      if (!shown && items.length) await selectFleet(items[0].id);
    }
  } catch (error) {
    if (!page.state) showMessage(`Cannot list the fleets: ${error.message}`, { alert: true });
  }
  page.fleetTimer = setTimeout(refreshFleets, page.fleets.length ? FLEET_POLL_MS : FLEET_POLL_EMPTY_MS);
}

// -- network ------------------------------------------------------------------

async function showNetwork(networkId) {
  if (map.networkId === networkId) return;
  let summary = page.networks.find((n) => n.id === networkId);
  if (!summary) summary = await api.get(`/v1/networks/${encodeURIComponent(networkId)}`);
  let geometry = page.geometry.get(networkId);
  if (!geometry) {
    geometry = await api.geometry(networkId);
    page.geometry.set(networkId, geometry);
  }
  map.setNetwork(summary, geometry);
}

async function showNoFleets() {
  page.token += 1;
  live.close("no fleet to follow");
  page.state = null;
  map.clearOverlays();
  for (const id of ["#post-panel", "#charts", "#recent"]) $(id).hidden = true;
  ui.noFleets.hidden = false;
  ui.summary.textContent = "";
  ui.legend.replaceChildren();
  body.dataset.fleet = "";
  body.dataset.version = "";
  const net = page.networks[0];
  if (!net) {
    showMessage("No road networks are loaded. Upload one with POST /v1/networks.");
    ui.noFleetsExample.textContent = "";
    body.dataset.state = "empty";
    return;
  }
  await showNetwork(net.id);
  const [xmin, ymin, xmax, ymax] = net.bounds;
  const x = Math.round((xmin + xmax) / 2);
  const y = Math.round((ymin + ymax) / 2);
  const example = {
    id: "city",
    network: net.id,
    vehicles: [
      { id: "v1", type: "A", position: { x, y } },
      { id: "v2", type: "B", position: { x: Math.round(xmin + (xmax - xmin) / 4), y } },
    ],
    reference_demand: { kind: "hotspots", count: 3 },
  };
  ui.noFleetsExample.textContent =
    `curl -X POST ${location.origin}${api.base}/v1/fleets \\\n  -H 'Content-Type: application/json' \\\n  -d '${JSON.stringify(example)}'`;
  showMessage(`No fleets yet. This is network “${net.id}”; create a fleet on it and it appears here.`);
  body.dataset.state = "empty";
}

// -- a fleet ------------------------------------------------------------------

async function selectFleet(fleetId) {
  const token = ++page.token;
  live.close("loading…");
  body.dataset.state = "loading";
  ui.noFleets.hidden = true;
  try {
    const metrics = await api.metrics(fleetId);
    const fleet = await api.fleet(fleetId);
    await showNetwork(fleet.network);
    const after = Math.max(0, metrics.version - HISTORY_EVENTS);
    const past = await api.events(fleetId, after, HISTORY_EVENTS);
    if (token !== page.token) return;
    const state = new FleetState(fleet, metrics);
    state.loadHistory(past.items);
    page.state = state;
    page.colors = typeColors(state.types);
    layer.reset(state, page.colors);
    panel.setFleet(state, page.colors);
    showMessage("");
    renderLegend(state);
    renderAll();
    clearTimeout(page.postsTimer); // a read still due for the fleet shown before
    page.postsTimer = 0;
    schedulePosts(state);
    const url = new URL(location.href);
    url.searchParams.set("fleet", fleetId);
    window.history.replaceState(null, "", url);
    body.dataset.fleet = fleetId;
    body.dataset.state = "ready";
    live.open(() => api.streamUrl(fleetId, state.version), {
      log: (event) => onLog(state, event),
      metrics: (metrics) => onMetrics(state, metrics),
      problem: (problem) => onProblem(state, problem),
    });
  } catch (error) {
    if (token !== page.token) return;
    body.dataset.state = "error";
    showMessage(`Could not load fleet “${fleetId}”: ${error.message}`, { alert: true });
  }
}

function onLog(state, event) {
  if (state !== page.state) return;
  if (!state.applyEvent(event)) return;
  if (state.deleted) {
    live.close("fleet deleted");
    showMessage(`Fleet “${state.id}” was deleted.`, { alert: true });
    refreshFleets();
  }
  if (event.kind === "target" || event.kind === "vehicle_state") schedulePosts(state);
  scheduleRender();
}

/** Ask for the posts (a read that changes nothing) half a second after the first event
 * since the last read: at most twice a second however fast the events come. */
function schedulePosts(state) {
  if (page.postsTimer) return;
  page.postsTimer = setTimeout(async () => {
    page.postsTimer = 0;
    if (state !== page.state || state.deleted) return;
    try {
      const answer = await api.posts(state.id);
      if (state === page.state) layer.renderPosts(state, answer);
    } catch (error) {
      // 404: the fleet was deleted meanwhile, which its live stream reports
      if (state === page.state && error.status !== 404) {
        showMessage(`Could not read the posts: ${error.message}`, { alert: true });
      }
    }
  }, POSTS_DELAY_MS);
}

function onMetrics(state, metrics) {
  if (state !== page.state) return;
  state.applyMetrics(metrics);
  scheduleRender();
}

function onProblem(state, problem) {
  if (state !== page.state) return;
  if (problem.status === 404) {
    live.close(problem.detail || "fleet gone");
    refreshFleets();
  } else {
    live.setStatus("connecting", `stream interrupted: ${problem.detail || problem.title}`);
  }
}

// -- rendering ----------------------------------------------------------------

function scheduleRender() {
  if (page.frame) return;
  page.frame = requestAnimationFrame(() => {
    page.frame = 0;
    renderAll({ chartsLater: true });
  });
}

function renderAll({ chartsLater = false } = {}) {
  const state = page.state;
  if (!state) return;
  layer.render(state);
  renderRecent(state);
  renderSummary(state);
  body.dataset.version = String(state.version);
  const wait = page.chartsDrawnAt + CHART_INTERVAL_MS - performance.now();
  if (!chartsLater || wait <= 0) {
    clearTimeout(page.chartTimer);
    page.chartTimer = 0;
    drawCharts();
  } else if (!page.chartTimer) {
    page.chartTimer = setTimeout(() => {
      page.chartTimer = 0;
      drawCharts();
    }, wait);
  }
}

function drawCharts() {
  if (!page.state) return;
  charts.render(page.state, page.colors);
  page.chartsDrawnAt = performance.now();
}

function renderSummary(state) {
  const counts = new Map();
  for (const v of state.vehicles.values()) counts.set(v.type, (counts.get(v.type) || 0) + 1);
  const types = state.types.map((t) => `${t}×${counts.get(t)}`).join(", ");
  ui.summary.textContent =
    `${state.vehicles.size} vehicles (${types}) · network ${state.network} · ${state.cost} cost · ` +
    `${state.objective} · ${state.targets} ${state.targets === 1 ? "target" : "targets"}`;
}

/** One legend entry: a swatch of `className` (and `background`, if given) and a label. */
function legendItem(className, text, background = "") {
  const li = document.createElement("li");
  const swatch = document.createElement("span");
  swatch.className = className;
  if (background) swatch.style.background = background;
  li.append(swatch, document.createTextNode(text));
  return li;
}

function renderLegend(state) {
  ui.legend.replaceChildren(
    ...state.types.map((type) => legendItem("swatch", `type ${type}`, page.colors.get(type))),
    legendItem("swatch target", "target"),
    legendItem("swatch line", "served by (dashed: did not move)"),
    legendItem("swatch post", "post of a free vehicle (dashed: on its way)"),
  );
}

function renderRecent(state) {
  ui.recent.hidden = false;
  const rows = state.recentTargets.slice(-RECENT_ROWS).reverse();
  ui.recentEmpty.hidden = rows.length > 0;
  ui.recentEmpty.textContent = rows.length ? "" : "None yet: this fleet has not served a target.";
  ui.recentRows.replaceChildren(
    ...rows.map((t, i) => {
      const tr = document.createElement("tr");
      if (i === 0) tr.className = "newest";
      tr.dataset.seq = String(t.seq);
      const cells = [
        String(t.seq),
        t.requires && t.requires.length ? t.requires.join("+") : "any",
        t.servedBy.join(", "),
        t.moved,
        `${fmt(t.cost)} ${state.unit}`,
      ];
      for (const text of cells) {
        const td = document.createElement("td");
        td.textContent = text;
        tr.append(td);
      }
      return tr;
    }),
  );
}

// -- controls -----------------------------------------------------------------

$("#zoom-in").addEventListener("click", () => map.zoomBy(1.5));
$("#zoom-out").addEventListener("click", () => map.zoomBy(1 / 1.5));
$("#zoom-fit").addEventListener("click", () => map.fit());
$("#show-trails").addEventListener("change", (e) => map.svg.classList.toggle("no-trails", !e.target.checked));
$("#show-targets").addEventListener("change", (e) => map.svg.classList.toggle("no-targets", !e.target.checked));
ui.select.addEventListener("change", () => ui.select.value && selectFleet(ui.select.value));

async function start() {
  try {
    const [networks, fleets] = await Promise.all([api.networks(), api.fleets()]);
    page.networks = networks.items;
    page.fleets = fleets.items;
  } catch (error) {
    body.dataset.state = "error";
    showMessage(`The service did not answer: ${error.message}`, { alert: true });
    return;
  }
  const wanted = new URLSearchParams(location.search).get("fleet");
  const chosen = page.fleets.find((f) => f.id === wanted) || page.fleets[0];
  fillFleetSelect(page.fleets, chosen && chosen.id);
  if (chosen) await selectFleet(chosen.id);
  else await showNoFleets();
  page.fleetTimer = setTimeout(refreshFleets, page.fleets.length ? FLEET_POLL_MS : FLEET_POLL_EMPTY_MS);
}

start();
