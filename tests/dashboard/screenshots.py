"""Make the README's dashboard screenshots (not a test).

Starts ``routing-svc serve`` on a fresh SQLite database with the DRT network,
creates a heterogeneous fleet whose reference demand is three hot spots (as
edge weights), opens the dashboard in headless Chromium, posts a few hundred
targets drawn from that demand while the page watches, and saves PNGs::

    python -m tests.dashboard.screenshots docs/figures/dashboard
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from playwright.sync_api import sync_playwright

from tests.dashboard.browser import CHROMIUM, CHROMIUM_ARGS, VIEWPORT, DashboardPage
from tests.dashboard.service_client import Edge, ServiceClient
from tests.helpers import LiveServer

FLEET = "city"
TYPES = ["A", "A", "A", "A", "B", "B", "B", "C", "C", "C"]
REQUIRES: list[list[str] | None] = [None, None, None, ["A"], ["B"], ["A", "B"], ["B", "C"]]
TARGETS = 400
BATCH = 20
SPREAD_M = 300.0
HOTSPOT_WEIGHTS = (0.5, 0.3, 0.2)


def hotspot_weights(edges: list[Edge], seed: int) -> dict[str, float]:
    """Demand per edge: its length times a mixture of three Gaussian hot spots."""
    rng = np.random.default_rng(seed)
    mids = np.array([e.midpoint for e in edges])
    centres = mids[rng.choice(len(edges), size=len(HOTSPOT_WEIGHTS), replace=False)]
    density = np.zeros(len(edges))
    for weight, centre in zip(HOTSPOT_WEIGHTS, centres, strict=True):
        density += weight * np.exp(-((mids - centre) ** 2).sum(axis=1) / (2 * SPREAD_M**2))
    lengths = np.array([e.length for e in edges])
    return {e.id: float(w) for e, w in zip(edges, lengths * density, strict=True) if w > 1e-9}


def sample_targets(
    edges: list[Edge], weights: dict[str, float], count: int, seed: int
) -> list[dict[str, Any]]:
    """Targets drawn from the edge weights (uniform along an edge), with mixed requirements."""
    rng = np.random.default_rng(seed)
    by_id = {e.id: e for e in edges}
    ids = list(weights)
    p = np.array([weights[i] for i in ids])
    out = []
    for k in rng.choice(len(ids), size=count, p=p / p.sum()):
        edge = by_id[ids[int(k)]]
        target: dict[str, Any] = {
            "position": {"edge": edge.id, "offset": float(rng.uniform(0, edge.length))}
        }
        requires = REQUIRES[int(rng.integers(len(REQUIRES)))]
        if requires:
            target["requires"] = requires
        out.append(target)
    return out


def click_a_target(dash: DashboardPage, api: ServiceClient, edges: list[Edge]) -> Path:
    """Zoom in on the busiest vehicle and post an A+B target there with a click."""
    page = dash.page
    busiest = max(api.fleet(FLEET)["vehicles"], key=lambda v: v["updates"])
    spot = (busiest["position"]["x"], busiest["position"]["y"])
    page.mouse.move(*dash.screen_point(*spot))
    page.mouse.wheel(0, -450)
    time.sleep(0.5)
    near = min(edges, key=lambda e: abs(math.dist(e.midpoint, spot) - 150.0))
    page.fill("#requires-inputs input[data-type='A']", "1")
    page.fill("#requires-inputs input[data-type='B']", "1")
    page.click("#place-target")
    page.mouse.click(*dash.screen_point(*near.midpoint))
    page.wait_for_selector("#post-result[data-seq]")
    seq = page.get_attribute("#post-result", "data-seq")
    page.wait_for_selector(f"g.target[data-seq='{seq}']")
    page.mouse.move(0, 0)
    time.sleep(0.5)
    return dash.screenshot("click-to-post")


def requirement_mix() -> list[dict[str, Any]]:
    """The classes of :data:`REQUIRES` with their shares (each entry is drawn equally
    often), so that the dashboard's gap is against the heterogeneous optimum."""
    shares: dict[tuple[str, ...], float] = {}
    for requires in REQUIRES:
        key = tuple(requires or ())
        shares[key] = shares.get(key, 0.0) + 1.0
    return [{"requires": list(k), "share": v} for k, v in shares.items()]


def make_screenshots(out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        server = LiveServer(f"sqlite:///{folder / 'events.db'}", folder).start()
        api = ServiceClient(server.url)
        try:
            edges = api.edges()
            weights = hotspot_weights(edges, seed=5)
            api.create_fleet(
                FLEET,
                TYPES,
                reference_demand={
                    "kind": "weights",
                    "weights": weights,
                    "requirements": requirement_mix(),
                },
            )
            targets = sample_targets(edges, weights, TARGETS, seed=3)
            api.post_batch(FLEET, targets[:BATCH])
            with sync_playwright() as playwright:
                browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
                context = browser.new_context(viewport=VIEWPORT)  # type: ignore[arg-type]
                dash = DashboardPage(context.new_page(), server.url, out).open(FLEET)
                for start in range(BATCH, TARGETS, BATCH):
                    api.post_batch(FLEET, targets[start : start + BATCH])
                    time.sleep(0.6)  # let the page take a metrics sample between batches
                dash.page.wait_for_selector(f"body[data-version='{TARGETS + 1}']")
                dash.page.mouse.move(0, 0)
                time.sleep(1.5)
                shots = [dash.screenshot("overview")]
                shots.append(click_a_target(dash, api, edges))
                problems = dash.problems()
                context.close()
                browser.close()
        finally:
            api.close()
            server.stop()
    if any(problems.values()):
        raise RuntimeError(f"the page reported problems: {problems}")
    return shots


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("out", type=Path, help="folder for the PNG files")
    args = parser.parse_args(argv)
    for path in make_screenshots(args.out):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
