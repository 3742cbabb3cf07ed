"""The dashboard in a real headless Chromium, against a live server on SQLite.

Each test saves a screenshot of what it checked in its ``tmp_path``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from tests.dashboard.browser import LIVE_UPDATE_MS, LOAD_MS, DashboardPage
from tests.dashboard.service_client import ServiceClient
from tests.helpers import LiveServer

OpenDashboard = Callable[[LiveServer], DashboardPage]
KEYBOARD_CONTROLS = {
    *("fleet-select", "zoom-in", "zoom-out", "zoom-fit", "show-trails", "show-targets"),
    *("map", "place-target", "post-centre"),
}
AVAILABLE, BUSY = "#1b7f3b", "#e67e22"
"""The fill of an available and of a busy vehicle (``STATUS_COLORS`` in fleet_layer.js)."""
CLEAN: dict[str, list[str]] = {"console_errors": [], "failed_requests": [], "external_requests": []}


def edge_position(api: ServiceClient, index: int, count: int = 12) -> dict[str, object]:
    """The middle of one of ``count`` edges spread over the network."""
    edge = api.spread_edges(count)[index]
    return {"edge": edge.id, "offset": edge.length / 2}


def test_page_loads_without_console_errors(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A", "A", "B"], reference_demand={"kind": "uniform"})
    for i in range(6):
        api.post_target(fleet_id, edge_position(api, i), requires=["A", "B"] if i % 2 else None)

    dash = open_dashboard(shared_server).open(fleet_id)
    dash.page.wait_for_selector("#chart-cost line[data-rule]", state="attached", timeout=LOAD_MS)
    dash.screenshot("loaded")

    assert dash.problems() == CLEAN
    assert dash.page.title() == "routing_svc · dashboard"
    assert dash.page.get_attribute("body", "data-fleet") == fleet_id
    assert dash.page.get_attribute("body", "data-version") == "7"

    # a small laptop screen: no sideways scrolling, the map keeps most of the width
    dash.page.set_viewport_size({"width": 1366, "height": 768})
    dash.page.wait_for_function("document.documentElement.scrollWidth <= window.innerWidth")
    assert dash.map_box()[2] > 900 and dash.map_box()[3] > 600
    dash.screenshot("laptop-1366x768")
    assert dash.problems() == CLEAN


def test_the_network_is_drawn(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A", "A"])
    geometry = api.geometry()
    dash = open_dashboard(shared_server).open(fleet_id)
    dash.screenshot("network")

    drawn = [f for f in geometry["features"] if len(f["geometry"]["coordinates"]) >= 2]
    assert dash.page.get_attribute("#map", "data-edges") == str(len(drawn))
    assert dash.page.get_attribute("#map", "data-network") == "drt"
    # The drawing spans the network's own coordinates (y drawn downwards) ...
    xs = [x for f in drawn for x, _ in f["geometry"]["coordinates"]]
    ys = [y for f in drawn for _, y in f["geometry"]["coordinates"]]
    box = dash.page.evaluate(
        "(() => { const b = document.querySelector('#edges').getBBox();"
        " return [b.x, b.y, b.width, b.height]; })()"
    )
    assert math.isclose(box[0], min(xs), abs_tol=0.01)
    assert math.isclose(box[1], -max(ys), abs_tol=0.01)
    assert math.isclose(box[0] + box[2], max(xs), abs_tol=0.01)
    assert math.isclose(box[1] + box[3], -min(ys), abs_tol=0.01)
    # ... and the whole of it is on screen, inside the map.
    left, top = dash.screen_point(min(xs), max(ys))
    right, bottom = dash.screen_point(max(xs), min(ys))
    x0, y0, width, height = dash.map_box()
    assert x0 <= left < right <= x0 + width
    assert y0 <= top < bottom <= y0 + height
    assert right - left > 0.8 * width or bottom - top > 0.8 * height
    assert dash.problems() == CLEAN


def test_vehicles_appear_where_the_api_says(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A", "B", "C", "A", "B", "C"])
    for i in range(8):
        api.post_target(fleet_id, edge_position(api, i), requires=["A", "B", "C"][i % 3 :][:1])
    fleet = api.fleet(fleet_id)

    dash = open_dashboard(shared_server).open(fleet_id)
    shown = dash.vehicles()
    dash.screenshot("vehicles")

    assert set(shown) == {v["id"] for v in fleet["vehicles"]}
    for vehicle in fleet["vehicles"]:
        mark = shown[vehicle["id"]]
        x, y = vehicle["position"]["x"], vehicle["position"]["y"]
        assert (mark["x"], mark["y"]) == (x, y)
        assert (mark["cx"], mark["cy"]) == (x, -y)
        assert mark["type"] == vehicle["type"]
        # the marker is drawn on screen where the map puts that network point
        assert math.dist(mark["screen"], mark["projected"]) < 1.0
        assert math.dist(mark["screen"], dash.screen_point(x, y)) < 1.0
    # the type is the ring, the status the fill
    colours = {mark["type"]: mark["stroke"] for mark in shown.values()}
    assert all(mark["stroke"] == colours[mark["type"]] for mark in shown.values())
    assert len(set(colours.values())) == 3
    assert {(mark["status"], mark["fill"]) for mark in shown.values()} == {("available", AVAILABLE)}
    assert dash.problems() == CLEAN


def test_a_posted_target_moves_the_right_vehicle_within_two_seconds(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    # the paper's rule: every target moves the vehicle that arrives last
    api.create_fleet(fleet_id, ["A", "B", "A", "B"], rule="paper")
    dash = open_dashboard(shared_server).open(fleet_id)
    before = dash.vehicles()

    result = api.post_target(fleet_id, edge_position(api, 5), requires=["A", "B"])
    new = result["new_position"]
    dash.wait_vehicle_at(result["moved"], new["x"], new["y"], timeout=LIVE_UPDATE_MS)
    dash.page.wait_for_selector(f"g.target[data-seq='{result['seq']}']", timeout=LIVE_UPDATE_MS)
    dash.screenshot("target-moves-vehicle")

    assert (new["x"], new["y"]) != (before[result["moved"]]["x"], before[result["moved"]]["y"])
    after = dash.vehicles()
    for vehicle, mark in after.items():
        if vehicle != result["moved"]:
            assert (mark["x"], mark["y"]) == (before[vehicle]["x"], before[vehicle]["y"])
    target = dash.page.locator(f"g.target[data-seq='{result['seq']}']")
    assert target.get_attribute("data-requires") == "A,B"
    assert target.get_attribute("data-moved") == result["moved"]
    assert target.get_attribute("data-served-by") == ",".join(result["served_by"])
    assert float(target.get_attribute("data-x") or "nan") == result["target"]["x"]
    assert target.locator("text.target-label").text_content() == "A+B"
    links = dash.page.locator(f"line.link[data-target='{result['seq']}']")
    assert sorted(links.evaluate_all("ls => ls.map(l => l.dataset.vehicle)")) == sorted(
        result["served_by"]
    )
    row = dash.page.locator(f"#recent-table tr[data-seq='{result['seq']}']")
    assert row.locator("td").all_inner_texts()[:4] == [
        str(result["seq"]),
        "A+B",
        ", ".join(result["served_by"]),
        result["moved"],
    ]
    assert dash.problems() == CLEAN


def test_clicking_on_the_map_posts_a_target(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A", "B", "B"])
    dash = open_dashboard(shared_server).open(fleet_id)
    page = dash.page
    page.fill("#requires-inputs input[data-type='A']", "1")
    page.fill("#requires-inputs input[data-type='B']", "2")
    page.click("#place-target")
    assert page.get_attribute("#place-target", "aria-pressed") == "true"

    spot = api.spread_edges(12)[7].midpoint
    metres_per_pixel = dash.view_box()[2] / dash.map_box()[2]
    page.mouse.click(*dash.screen_point(*spot))
    page.wait_for_selector("#post-result[data-seq]", timeout=LOAD_MS)
    seq = int(page.get_attribute("#post-result", "data-seq") or "0")

    (event,) = api.events(fleet_id, after=seq - 1)
    assert event["kind"] == "target"
    result = event["result"]
    assert result["requires"] == ["A", "B", "B"]
    assert sorted(result["served_by"]) == ["v1", "v2", "v3"]
    clicked_at = (result["target"]["x"], result["target"]["y"])
    assert math.dist(clicked_at, spot) < 3 * metres_per_pixel + 1.0
    new = result["new_position"]
    dash.wait_vehicle_at(result["moved"], new["x"], new["y"], timeout=LIVE_UPDATE_MS)
    page.wait_for_selector(f"g.target[data-seq='{seq}']", timeout=LIVE_UPDATE_MS)
    dash.screenshot("click-posts-target")
    assert dash.problems() == CLEAN


def test_pan_and_zoom_with_mouse_keys_and_buttons(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A", "A", "A"])
    dash = open_dashboard(shared_server).open(fleet_id)
    page = dash.page
    fit = dash.view_box()

    page.focus("#map")
    page.keyboard.press("+")
    zoomed = dash.view_box()
    assert math.isclose(zoomed[2], fit[2] / 1.5, rel_tol=1e-6)
    page.keyboard.press("ArrowRight")
    assert dash.view_box()[0] > zoomed[0]
    page.keyboard.press("-")
    page.keyboard.press("0")
    assert dash.view_box() == fit

    page.click("#zoom-in")
    page.click("#zoom-in")
    assert dash.view_box()[2] < fit[2] / 2
    page.click("#zoom-fit")
    assert dash.view_box() == fit

    left, top, width, height = dash.map_box()
    centre = (left + width / 2, top + height / 2)
    page.mouse.move(*centre)
    page.mouse.wheel(0, -400)
    page.wait_for_function(
        "w => Number(document.querySelector('#map').getAttribute('viewBox').split(' ')[2]) < w",
        arg=fit[2],
        timeout=LOAD_MS,
    )
    wheeled = dash.view_box()
    # the point under the cursor stays put while zooming
    assert math.isclose(wheeled[0] + wheeled[2] / 2, fit[0] + fit[2] / 2, rel_tol=1e-3, abs_tol=0.5)

    # a drag pans (and does not post a target, even while placing targets)
    page.click("#place-target")
    version = page.get_attribute("body", "data-version")
    page.mouse.move(*centre)
    page.mouse.down()
    for step in range(1, 11):
        page.mouse.move(centre[0] + 12 * step, centre[1])
    page.mouse.up()
    dragged = dash.view_box()
    assert math.isclose(dragged[0], wheeled[0] - 120 * wheeled[2] / width, rel_tol=1e-3)
    assert page.get_attribute("#post-result", "data-seq") is None
    assert page.get_attribute("body", "data-version") == version
    dash.screenshot("pan-zoom")
    assert dash.problems() == CLEAN


def test_controls_are_keyboard_accessible(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    first, second = f"{fleet_id}-1", f"{fleet_id}-2"
    api.create_fleet(first, ["A", "B"])
    api.create_fleet(second, ["A", "A", "A"])
    dash = open_dashboard(shared_server).open(first)
    page = dash.page

    reached = set()
    for _ in range(40):
        page.keyboard.press("Tab")
        reached.add(page.evaluate("document.activeElement.id || document.activeElement.tagName"))
    assert KEYBOARD_CONTROLS - reached == set()

    page.focus("#post-centre")
    page.keyboard.press("Enter")
    page.wait_for_selector("#post-result[data-seq]", timeout=LOAD_MS)
    seq = page.get_attribute("#post-result", "data-seq")
    page.wait_for_selector(f"g.target[data-seq='{seq}']", timeout=LIVE_UPDATE_MS)

    page.focus("#fleet-select")
    page.keyboard.press("ArrowDown")
    page.wait_for_selector(f"body[data-fleet='{second}'][data-state='ready']", timeout=LOAD_MS)
    assert set(dash.vehicles()) == {"v1", "v2", "v3"}
    assert page.locator("#requires-inputs").is_hidden()
    dash.screenshot("keyboard")
    assert dash.problems() == CLEAN


def test_charts_follow_the_targets(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A", "A", "B"], reference_demand={"kind": "uniform"})
    dash = open_dashboard(shared_server).open(fleet_id)
    page = dash.page
    assert page.locator("#charts-empty").is_visible()

    spots = api.spread_edges(30)
    results = api.post_batch(
        fleet_id,
        [
            {"position": {"edge": e.id, "offset": 0.0}, "requires": ["B"] if i % 3 == 0 else None}
            for i, e in enumerate(spots)
        ],
    )
    version = results[-1]["version"]
    page.wait_for_selector(f"body[data-version='{version}']", timeout=LIVE_UPDATE_MS)
    page.wait_for_selector("#chart-step svg[data-points='30']", timeout=LOAD_MS)
    dash.screenshot("charts")

    assert page.locator("#charts-empty").is_hidden()
    cost = page.locator("#chart-cost svg")
    assert cost.get_attribute("data-points") is not None
    mean_points = cost.locator("polyline[data-series='mean, whole run']").get_attribute("points")
    assert mean_points is not None and len(mean_points.split()) == 30
    assert cost.locator("line[data-rule]").count() == 1
    mean = sum(r["cost"] for r in results) / len(results)
    readout = float(page.get_attribute("#chart-cost .readout", "data-mean") or "nan")
    assert math.isclose(readout, mean, rel_tol=1e-9)
    assert "optimum" in page.inner_text("#chart-cost .readout")
    bars = page.locator("#chart-updates rect[data-bar]")
    names = bars.evaluate_all("bs => bs.map(b => b.dataset.bar)")
    values = bars.evaluate_all("bs => bs.map(b => Number(b.dataset.value))")
    counts = dict(zip(names, values, strict=True))
    moved = [r["moved"] for r in results]
    assert counts == {v: moved.count(v) for v in ("v1", "v2", "v3")}
    assert dash.problems() == CLEAN


def test_the_past_and_live_targets_join_up(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A", "B", "B"])
    spots = [{"position": {"edge": e.id, "offset": 1.0}} for e in api.spread_edges(20)]
    before = api.post_batch(fleet_id, spots[:12])
    dash = open_dashboard(shared_server).open(fleet_id)
    page = dash.page
    after = api.post_batch(fleet_id, spots[12:])
    page.wait_for_selector("body[data-version='21']", timeout=LIVE_UPDATE_MS)
    page.wait_for_selector("#chart-step svg[data-points='20']", timeout=LOAD_MS)
    dash.screenshot("past-and-live")

    results = before + after
    mean_line = page.get_attribute("#chart-cost polyline[data-series='mean, whole run']", "points")
    assert mean_line is not None and len(mean_line.split()) == 20
    readout = float(page.get_attribute("#chart-cost .readout", "data-mean") or "nan")
    assert math.isclose(readout, sum(r["cost"] for r in results) / 20, rel_tol=1e-9)
    rows = page.locator("#recent-table tbody tr")
    assert rows.first.get_attribute("data-seq") == "21"
    assert page.locator("g.target").count() == 15  # the most recent ones
    fleet = api.fleet(fleet_id)
    shown = dash.vehicles()
    for vehicle in fleet["vehicles"]:
        position = vehicle["position"]
        assert (shown[vehicle["id"]]["x"], shown[vehicle["id"]]["y"]) == (
            position["x"],
            position["y"],
        )
        assert page.get_attribute(f"circle[data-vehicle='{vehicle['id']}']", "data-updates") == str(
            vehicle["updates"]
        )
    assert dash.problems() == CLEAN


def test_empty_states(
    empty_server: LiveServer,
    connect: Callable[[LiveServer], ServiceClient],
    open_dashboard: OpenDashboard,
) -> None:
    dash = open_dashboard(empty_server).open(state="empty")
    page = dash.page
    assert page.locator("#no-fleets").is_visible()
    assert "No fleets yet" in page.inner_text("#map-message")
    assert page.is_disabled("#fleet-select")
    assert int(page.get_attribute("#map", "data-edges") or "0") > 100
    assert '"network":"drt"' in page.inner_text("#no-fleets-example")
    dash.screenshot("no-fleets")

    connect(empty_server).create_fleet("first", ["A", "B"])
    dash.wait_state("ready")
    page.wait_for_selector("body[data-fleet='first']", timeout=LOAD_MS)
    assert page.locator("#no-fleets").is_hidden()
    assert "No targets yet" in page.inner_text("#charts-empty")
    assert "None yet" in page.inner_text("#recent-empty")
    assert page.locator("#chart-cost svg text.nodata").count() == 1
    dash.screenshot("no-targets")
    assert dash.problems() == CLEAN


def test_a_deleted_fleet_is_reported(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A"])
    dash = open_dashboard(shared_server).open(fleet_id)
    # its first read of the posts is answered before the fleet goes (a read on its way
    # then is answered 404, which the browser reports whatever the page does with it)
    dash.page.wait_for_selector("#layer-posts[data-version='1']", state="attached", timeout=LOAD_MS)
    assert api.http.delete(f"/v1/fleets/{fleet_id}").status_code == 204
    dash.page.wait_for_selector("#live-status[data-live='idle']", timeout=LOAD_MS)
    assert dash.page.inner_text("#map-message") == f"Fleet “{fleet_id}” was deleted."
    assert dash.page.inner_text("#live-status") == "fleet deleted"
    dash.page.wait_for_selector(
        f"#fleet-select option[value='{fleet_id}'][disabled]", state="attached", timeout=LOAD_MS
    )
    assert dash.page.get_attribute("body", "data-fleet") == fleet_id
    dash.screenshot("deleted")
    assert dash.problems() == CLEAN


def test_vehicle_states_dispatch_lines_and_service_levels_are_drawn(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A", "A", "A"], rule="paper")
    dash = open_dashboard(shared_server).open(fleet_id)
    target = edge_position(api, 4)
    busy = api.post_target(fleet_id, target)["dispatch"]["vehicles"][0]["vehicle"]
    away = edge_position(api, 11)
    shown = api.set_state(fleet_id, busy, {"status": "busy", "position": away})["vehicles"][0]
    result = api.post_target(fleet_id, target)
    (sent,) = [s["vehicle"] for s in result["dispatch"]["vehicles"]]
    assert sent != busy
    line = f"line.dispatch[data-target='{result['seq']}'][data-vehicle='{sent}']"
    dash.page.wait_for_selector(line, state="attached", timeout=LIVE_UPDATE_MS)
    dash.page.wait_for_selector(
        f"circle.vehicle[data-vehicle='{busy}'][data-status='busy']", state="attached"
    )
    dash.page.wait_for_selector("#chart-levels polyline.series", state="attached", timeout=LOAD_MS)
    dash.screenshot("vehicle-states")

    marks = dash.vehicles()
    assert (marks[busy]["status"], marks[busy]["fill"]) == ("busy", BUSY)
    # drawn at its current position, tied to its reference
    assert (marks[busy]["cx"], marks[busy]["cy"]) == (shown["current"]["x"], -shown["current"]["y"])
    anchor = dash.page.locator(f"line.anchor[data-vehicle='{busy}']")
    assert anchor.get_attribute("class") == "anchor away"
    assert float(anchor.get_attribute("x2") or "nan") == shown["reference"]["x"]
    assert dash.page.locator("line.dispatch").count() == 1
    levels = dash.page.locator("#chart-levels polyline.series")
    assert levels.count() == 3  # one line per threshold
    assert dash.problems() == CLEAN


def test_posts_are_drawn_where_the_service_says_the_free_vehicles_should_wait(
    shared_server: LiveServer, api: ServiceClient, fleet_id: str, open_dashboard: OpenDashboard
) -> None:
    api.create_fleet(fleet_id, ["A", "A", "A", "A"], rule="paper")
    dash = open_dashboard(shared_server).open(fleet_id)
    first = api.posts(fleet_id)
    dash.page.wait_for_selector(
        f"#layer-posts[data-version='{first['version']}']", state="attached", timeout=LOAD_MS
    )
    assert dash.page.locator("#layer-posts circle.post").count() == 4
    busy = api.post_target(fleet_id, edge_position(api, 4))["dispatch"]["vehicles"][0]["vehicle"]
    api.set_state(fleet_id, busy, {"status": "busy", "position": edge_position(api, 11)})
    answer = api.posts(fleet_id)
    dash.page.wait_for_selector(
        f"#layer-posts[data-version='{answer['version']}']", state="attached", timeout=LOAD_MS
    )
    dash.screenshot("posts")

    drawn = dash.page.eval_on_selector_all(
        "#layer-posts circle.post",
        """rings => rings.map(r => [r.dataset.postOf, r.dataset.referenceOf,
            Number(r.dataset.x), Number(r.dataset.y)])""",
    )
    expected = [
        [p["vehicle"], p["reference_of"], p["position"]["x"], p["position"]["y"]]
        for p in answer["posts"]
    ]
    assert sorted(drawn) == sorted(expected)
    assert len(drawn) == 3 and busy not in {row[0] for row in drawn}
    # a dashed line from each vehicle not yet at its post, none from the others
    away = sorted(p["vehicle"] for p in answer["posts"] if p["time"] > 0)
    lines = dash.page.eval_on_selector_all(
        "#layer-posts line.post-line", "lines => lines.map(l => l.dataset.postOf)"
    )
    assert sorted(lines) == away
    assert dash.problems() == CLEAN
