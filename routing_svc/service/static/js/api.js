/**
 * A small client of the REST API (docs/api.md): JSON in, JSON out, and every
 * error as an ApiError carrying the service's problem+json document.
 */

export class ApiError extends Error {
  /**
   * @param {number} status HTTP status (0 when the service could not be reached)
   * @param {{title?: string, detail?: string}} problem the problem document
   */
  constructor(status, problem) {
    super(problem.detail || problem.title || `HTTP ${status}`);
    this.status = status;
    this.problem = problem;
  }
}

export class Api {
  /** @param {string} base path prefix of the service ("" when mounted at the root) */
  constructor(base) {
    this.base = base;
    /** @type {string} sent as X-API-Key on writes when not empty */
    this.apiKey = "";
  }

  async request(method, path, body) {
    const headers = { Accept: "application/json" };
    if (body !== undefined) headers["Content-Type"] = "application/json";
    if (method !== "GET" && this.apiKey) headers["X-API-Key"] = this.apiKey;
    let response;
    try {
      response = await fetch(this.base + path, {
        method,
        headers,
        body: body === undefined ? undefined : JSON.stringify(body),
      });
    } catch (error) {
      throw new ApiError(0, { title: "Service unreachable", detail: String(error.message || error) });
    }
    const text = await response.text();
    let data = null;
    if (text) {
      try {
        data = JSON.parse(text);
      } catch {
        data = { detail: text.slice(0, 200) };
      }
    }
    if (!response.ok) throw new ApiError(response.status, data || {});
    return data;
  }

  get(path) {
    return this.request("GET", path);
  }

  post(path, body) {
    return this.request("POST", path, body);
  }

  networks() {
    return this.get("/v1/networks");
  }

  geometry(networkId) {
    return this.get(`/v1/networks/${encodeURIComponent(networkId)}/geometry`);
  }

  fleets() {
    return this.get("/v1/fleets");
  }

  fleet(fleetId) {
    return this.get(`/v1/fleets/${encodeURIComponent(fleetId)}`);
  }

  metrics(fleetId) {
    return this.get(`/v1/fleets/${encodeURIComponent(fleetId)}/metrics`);
  }

  events(fleetId, after, limit) {
    return this.get(`/v1/fleets/${encodeURIComponent(fleetId)}/events?after=${after}&limit=${limit}`);
  }

  /** Where each available vehicle should wait now (GET .../posts; changes nothing). */
  posts(fleetId) {
    return this.get(`/v1/fleets/${encodeURIComponent(fleetId)}/posts`);
  }

  postTarget(fleetId, target) {
    return this.post(`/v1/fleets/${encodeURIComponent(fleetId)}/targets`, target);
  }

  /** URL of the fleet's Server-Sent Events stream, starting after event `after`. */
  streamUrl(fleetId, after) {
    return `${this.base}/v1/fleets/${encodeURIComponent(fleetId)}/stream?after=${after}`;
  }
}
