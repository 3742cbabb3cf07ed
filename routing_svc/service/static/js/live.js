/**
 * The live feed of one fleet: an EventSource on GET /v1/fleets/{id}/stream.
 *
 * The browser reconnects on its own after a dropped connection (the server
 * also ends every stream after a while) and resumes from the last event id it
 * saw. When the connection fails for good (e.g. the service restarted and the
 * browser gave up), the feed opens a new one after a pause, from the last
 * applied event.
 */

const REOPEN_MS = 3000;

export class LiveFeed {
  /** @param {HTMLElement} status element whose text and data-live show the state */
  constructor(status) {
    this.status = status;
    this.source = null;
    this.timer = null;
  }

  setStatus(state, text) {
    this.status.dataset.live = state;
    this.status.textContent = text;
  }

  /**
   * @param {() => string} url the stream URL to (re)connect to
   * @param {{log: (e: object) => void, metrics: (m: object) => void, problem: (p: object) => void}} on
   */
  open(url, on) {
    this.close();
    this.url = url;
    this.on = on;
    this.connect();
  }

  connect() {
    const source = new EventSource(this.url());
    this.source = source;
    this.setStatus("connecting", "connecting…");
    source.addEventListener("open", () => this.setStatus("open", "live"));
    source.addEventListener("log", (message) => this.on.log(JSON.parse(message.data)));
    source.addEventListener("metrics", (message) => this.on.metrics(JSON.parse(message.data)));
    source.addEventListener("problem", (message) => this.on.problem(JSON.parse(message.data)));
    source.addEventListener("error", () => {
      if (this.source !== source) return;
      if (source.readyState === EventSource.CLOSED) {
        this.setStatus("closed", "offline, retrying…");
        this.timer = setTimeout(() => this.connect(), REOPEN_MS);
      } else {
        this.setStatus("connecting", "reconnecting…");
      }
    });
  }

  /** Stop for good (another fleet was chosen, or this one was deleted). */
  close(text = "not connected") {
    clearTimeout(this.timer);
    if (this.source) this.source.close();
    this.source = null;
    this.setStatus("idle", text);
  }
}
