/**
 * The "Post a target" panel: how many vehicles of each type the target needs,
 * a mode in which a click on the map posts a target there, and a button that
 * posts one at the centre of the view (the keyboard way to do the same).
 */

import { fmt } from "./svg.js";

const MAX_PER_TYPE = 9;
const API_KEY_STORE = "routing_svc.apiKey";

export class TargetPanel {
  /**
   * @param {HTMLElement} root the panel
   * @param {{api: import("./api.js").Api, map: import("./map.js").NetworkMap,
   *          layer: import("./fleet_layer.js").FleetLayer}} deps
   */
  constructor(root, { api, map, layer }) {
    this.root = root;
    this.api = api;
    this.map = map;
    this.layer = layer;
    this.state = null;
    this.inputs = root.querySelector("#requires-inputs");
    this.hint = root.querySelector("#requires-hint");
    this.placeButton = root.querySelector("#place-target");
    this.centreButton = root.querySelector("#post-centre");
    this.result = root.querySelector("#post-result");
    this.keyInput = root.querySelector("#api-key");
    this.keyInput.value = sessionStorage.getItem(API_KEY_STORE) || "";
    this.api.apiKey = this.keyInput.value;
    root.querySelector("#api-key-form").addEventListener("submit", (event) => event.preventDefault());
    this.keyInput.addEventListener("input", () => {
      this.api.apiKey = this.keyInput.value.trim();
      sessionStorage.setItem(API_KEY_STORE, this.api.apiKey);
    });
    this.placeButton.addEventListener("click", () => this.setPlacing(!this.placing));
    this.centreButton.addEventListener("click", () => this.post(this.map.centre()));
    this.placing = false;
  }

  /** Show the panel for a fleet: one count per vehicle type. */
  setFleet(state, colors) {
    this.state = state;
    this.root.hidden = false;
    this.result.textContent = "";
    this.result.classList.remove("error");
    this.inputs.replaceChildren();
    if (!state.heterogeneous) {
      this.hint.textContent = `All vehicles are of type ${state.types[0]}: the nearest one serves each target.`;
      this.inputs.hidden = true;
      return;
    }
    this.inputs.hidden = false;
    this.hint.textContent = "All zero: the nearest vehicle of any type serves it.";
    for (const type of state.types) {
      const label = document.createElement("label");
      const swatch = document.createElement("span");
      swatch.className = "swatch";
      swatch.style.background = colors.get(type);
      const input = document.createElement("input");
      input.type = "number";
      input.min = "0";
      input.max = String(MAX_PER_TYPE);
      input.step = "1";
      input.value = "0";
      input.dataset.type = type;
      input.setAttribute("aria-label", `vehicles of type ${type} required`);
      label.append(swatch, document.createTextNode(type), input);
      this.inputs.append(label);
    }
  }

  /** The required types as the API wants them (a multiset; null for "any one vehicle"). */
  requires() {
    const out = [];
    for (const input of this.inputs.querySelectorAll("input[data-type]")) {
      const count = Math.max(0, Math.min(MAX_PER_TYPE, Math.floor(Number(input.value) || 0)));
      for (let i = 0; i < count; i += 1) out.push(input.dataset.type);
    }
    return out.length ? out : null;
  }

  setPlacing(on) {
    this.placing = on;
    this.placeButton.setAttribute("aria-pressed", String(on));
    this.placeButton.textContent = on ? "Placing: click the map" : "Place on map";
    this.map.svg.classList.toggle("placing", on);
  }

  /** A click on the map: post a target there when placing. */
  onMapClick(point) {
    if (this.placing) this.post(point);
  }

  async post(point) {
    const state = this.state;
    if (!state || state.deleted) return;
    const body = { position: { x: point.x, y: point.y } };
    const requires = this.requires();
    if (requires) body.requires = requires;
    const pending = this.layer.showPending(point);
    this.result.classList.remove("error");
    this.result.textContent = `posting at (${point.x.toFixed(0)}, ${point.y.toFixed(0)})…`;
    try {
      const r = await this.api.postTarget(state.id, body);
      const others = r.served_by.filter((id) => id !== r.moved);
      this.result.textContent =
        `#${r.seq}: ${r.moved} moved ${fmt(r.moved_by)} ${state.unit} toward it` +
        (others.length ? ` (also served by ${others.join(", ")})` : "") +
        `; cost ${fmt(r.cost)} ${state.unit}.`;
      this.result.dataset.seq = String(r.seq);
    } catch (error) {
      this.result.classList.add("error");
      this.result.textContent = error.status === 401 ? "The service needs an API key (see “API key”)." : `Not posted: ${error.message}`;
    } finally {
      pending.remove();
    }
  }
}
