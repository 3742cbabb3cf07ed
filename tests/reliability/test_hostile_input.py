"""Issue 6, item 6: hostile input against a live server.

Each is rejected with a 4xx problem (its time is printed with the figures and
measured against a baseline by ``bench/hostile_xml.py``, not asserted) and
under 100 MiB of extra peak memory (``VmHWM`` of the server process), and none
changes state. An external entity pointing at a listener of this test makes no
connection to it and reads no file.
"""

from __future__ import annotations

import gzip
import socket
import time
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx

from routing_svc.network.xml_limits import MAX_ATTRIBUTE_BYTES, MAX_ATTRIBUTES, MAX_TEXT_CHARS
from tests.helpers import LiveServer, fleet_body, record_figures, vm_kib

MiB = 1024 * 1024


def gzip_bomb(size: int) -> bytes:
    """``size`` zero bytes, gzip-compressed (about 1/1000 of the size)."""
    z = zlib.compressobj(9, zlib.DEFLATED, 31)
    chunk = bytes(MiB)
    return b"".join(z.compress(chunk) for _ in range(size // MiB)) + z.flush()


def laughs(levels: int) -> bytes:
    ents = ['<!ENTITY l0 "lollollollollol">']
    ents += [f'<!ENTITY l{i} "{f"&l{i - 1};" * 10}">' for i in range(1, levels + 1)]
    return f'<?xml version="1.0"?><!DOCTYPE net [{"".join(ents)}]><net>&l{levels};</net>'.encode()


def chunks(total: int) -> Iterator[bytes]:
    block = b"x" * MiB
    for _ in range(total // MiB):
        yield block


def test_hostile_inputs_are_rejected_fast_and_small(
    server: Callable[..., LiveServer], tmp_path: Path
) -> None:
    live = server()
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    listener.setblocking(False)
    lport = listener.getsockname()[1]
    xxe_file = (
        b'<?xml version="1.0"?><!DOCTYPE net [<!ENTITY x SYSTEM "file:///etc/passwd">]>'
        b'<net version="1.9"><edge id="&x;"/></net>'
    )
    xxe_net = (
        f'<?xml version="1.0"?><!DOCTYPE net [<!ENTITY x SYSTEM "http://127.0.0.1:{lport}/e">'
        f']><net version="1.9"><edge id="&x;"/></net>'
    ).encode()
    xxe_dtd = (
        f'<?xml version="1.0"?><!DOCTYPE net SYSTEM "http://127.0.0.1:{lport}/d.dtd">'
        f'<net version="1.9"/>'
    ).encode()
    uploads: dict[str, object] = {
        "xxe_file": xxe_file,
        "xxe_network": xxe_net,
        "xxe_external_dtd": xxe_dtd,
        "billion_laughs": laughs(9),
        "quadratic_blowup": b'<!DOCTYPE n [<!ENTITY a "'
        + b"a" * 50_000
        + b'">]><net>'
        + b"&a;" * 50_000
        + b"</net>",
        "deep_nesting": b"<net>" + b"<a>" * 200_000 + b"</a>" * 200_000 + b"</net>",
        "gzip_bomb_1GiB": gzip_bomb(1024 * MiB),
        "huge_declared_body_70MiB": b"x" * (70 * MiB),
        "huge_chunked_body_70MiB": chunks(70 * MiB),
        "junk_under_the_limit_60MiB": b"<" * (60 * MiB),
    }
    httpx.post(live.url + "/v1/fleets", json=fleet_body()).raise_for_status()
    assert live.process is not None
    pid = live.process.pid
    before_state = httpx.get(live.url + "/v1/fleets/f1").json()
    hwm0 = vm_kib(pid, "VmHWM")
    figures: dict[str, object] = {"hwm_start_mib": round(hwm0 / 1024, 1)}
    with httpx.Client(base_url=live.url, timeout=30) as http:
        for name, data in uploads.items():
            t0 = time.monotonic()
            r = http.post("/v1/networks", params={"name": "evil"}, content=data)  # type: ignore[arg-type]
            elapsed = time.monotonic() - t0
            assert 400 <= r.status_code < 500, (name, r.status_code, r.text[:300])
            assert r.headers["content-type"].startswith("application/problem+json"), name
            assert "root:" not in r.text, name
            growth = (vm_kib(pid, "VmHWM") - hwm0) / 1024
            assert growth < 100, (name, growth)
            figures[name] = {"status": r.status_code, "s": round(elapsed, 3)}
        figures["hwm_growth_mib"] = round((vm_kib(pid, "VmHWM") - hwm0) / 1024, 1)
        # numbers, ids and types on the JSON routes: problem+json, no state change
        bad = [
            b'{"position": {"x": NaN, "y": 0}}',
            b'{"position": {"x": Infinity, "y": 0}}',
            b'{"position": {"x": 1e999, "y": 0}}',
            b'{"position": {"edge": "E", "offset": 1e308}}',
            b'{"position": {"x": 1e308, "y": -1e308}}',
            b'{"position": {"edge": 12, "offset": "a"}}',
            b'{"position": {"edge": "no-such-edge"}}',
            b'{"position": [1, 2]}',
            b'{"position": {"lon": 1, "lat": 1}, "requires": "A"}',
            b"[]",
            b'{"position": {"edge": "' + b"e" * 10_000 + b'"}}',
        ]
        for raw in bad:
            for path in (
                "/v1/fleets/f1/targets",
                "/v1/fleets/f1/assign",
                "/v1/fleets/nope/targets",
            ):
                r = http.post(path, content=raw, headers={"content-type": "application/json"})
                assert 400 <= r.status_code < 500, (path, raw[:60], r.status_code)
                assert r.headers["content-type"].startswith("application/problem+json")
        assert http.get("/v1/fleets/f1").json() == before_state
        assert [n["id"] for n in http.get("/v1/networks").json()["items"]] == ["drt"]
    try:
        conn, _ = listener.accept()
        conn.close()
        connected = True
    except BlockingIOError:
        connected = False
    listener.close()
    assert not connected, "the server fetched an external entity"
    record_figures("hostile_input", figures, tmp_path)


BOLOGNA = Path(__file__).resolve().parents[3] / "shared" / "nets" / "bologna.net.xml.gz"
LOCATION = b"<location "


def bologna_with(insert: bytes, *, into_location: bool = False) -> bytes:
    """Bologna's network with ``insert`` before its ``<location>`` element (or inside its tag)."""
    plain = gzip.decompress(BOLOGNA.read_bytes())
    at = plain.index(LOCATION)
    if into_location:
        at += len(LOCATION)
    return plain[:at] + insert + plain[at:]


def location_attributes(total: int) -> bytes:
    """Extra attributes that give Bologna's ``<location>`` (4 of its own) ``total`` in all."""
    return b"".join(b'x%d="1" ' % i for i in range(total - 4))


def test_xml_limits_hold_against_a_live_server(
    server: Callable[..., LiveServer], tmp_path: Path
) -> None:
    """Issue 23: the four hostile uploads of 40 MiB (and 2 million attributes) and
    each limit just under (a real network that is accepted) and just over (422
    naming the limit), plain and gzip, each within 100 MiB of extra peak memory."""
    value_tag = b'<edge id="e" shape="' + b"a" * (40 * MiB) + b'"/>'
    crowded = b"<edge " + b" ".join(b'a%d="1"' % i for i in range(2_000_000)) + b"/>"
    hostile: dict[str, tuple[bytes, str]] = {
        "junk_40MiB": (b"<" * (40 * MiB), "Invalid network"),
        "attribute_value_40MiB": (b"<net>" + value_tag + b"</net>", "MAX_ATTRIBUTE_BYTES"),
        "text_40MiB": (b"<net><edge>" + b"t" * (40 * MiB) + b"</edge></net>", "MAX_TEXT_CHARS"),
        "attributes_2M": (b"<net>" + crowded + b"</net>", "MAX_ATTRIBUTES"),
    }
    pad = b"<pad>%s</pad>"
    for limit, name, make in (
        (MAX_ATTRIBUTE_BYTES, "MAX_ATTRIBUTE_BYTES", lambda n: b'pad="' + b"1" * n + b'" '),
        (MAX_ATTRIBUTES, "MAX_ATTRIBUTES", location_attributes),
        (MAX_TEXT_CHARS, "MAX_TEXT_CHARS", lambda n: pad % (b"t" * n)),
    ):
        into = name != "MAX_TEXT_CHARS"
        hostile[f"{name}_under"] = (bologna_with(make(limit), into_location=into), "")
        hostile[f"{name}_over"] = (bologna_with(make(limit + 1), into_location=into), name)
    live = server()
    assert live.process is not None
    pid = live.process.pid
    hwm0 = vm_kib(pid, "VmHWM")
    figures: dict[str, object] = {"hwm_start_mib": round(hwm0 / 1024, 1)}
    with httpx.Client(base_url=live.url, timeout=60) as http:
        for case, (document, expected) in hostile.items():
            for form in ("plain", "gzip"):
                body = gzip.compress(document, compresslevel=6) if form == "gzip" else document
                t0 = time.monotonic()
                name = f"{case}-{form}".lower().replace("_", "-")
                r = http.post("/v1/networks", params={"name": name}, content=body)
                elapsed = time.monotonic() - t0
                growth = (vm_kib(pid, "VmHWM") - hwm0) / 1024
                figures[name] = {"status": r.status_code, "s": round(elapsed, 3)}
                if not expected:
                    assert r.status_code == 201, (name, r.text[:300])
                else:
                    assert r.status_code == 422, (name, r.status_code, r.text[:300])
                    problem = r.json()
                    assert r.headers["content-type"].startswith("application/problem+json")
                    if expected.startswith("MAX_"):
                        assert problem["title"] == "XML limit exceeded", (name, problem)
                        assert problem["limit"] == expected, (name, problem)
                        assert str(problem["maximum"]) in problem["detail"], (name, problem)
                    else:
                        assert problem["title"] == expected, (name, problem)
                assert growth < 100, (name, growth)
        accepted = {n["id"] for n in http.get("/v1/networks").json()["items"]}
    figures["hwm_growth_mib"] = round((vm_kib(pid, "VmHWM") - hwm0) / 1024, 1)
    assert accepted == {"drt"} | {
        f"{name}-under-{form}".lower().replace("_", "-")
        for name in ("MAX_ATTRIBUTE_BYTES", "MAX_ATTRIBUTES", "MAX_TEXT_CHARS")
        for form in ("plain", "gzip")
    }
    record_figures("xml_limits", figures, tmp_path)
