"""A refused network upload leaves nothing behind: no file, no network, on each backend."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from tests.helpers import DRT

PLAIN = Path(DRT).read_bytes()


def kept_files(tmp_path: Path) -> set[str]:
    folder = tmp_path / "networks"
    return {p.name for p in folder.iterdir()} if folder.exists() else set()


def test_a_network_without_edges_is_refused_and_its_file_taken_back(
    client: TestClient, tmp_path: Path
) -> None:
    before = kept_files(tmp_path)
    listed = client.get("/v1/networks").json()
    answer = client.post("/v1/networks?name=empty", content=b'<net version="1.20"></net>')
    assert answer.status_code == 422
    assert answer.headers["content-type"] == "application/problem+json"
    assert kept_files(tmp_path) == before
    assert client.get("/v1/networks").json() == listed
    assert client.get("/v1/networks/empty").status_code == 404


def test_a_network_without_a_loop_is_refused_and_its_file_taken_back(
    client: TestClient, tmp_path: Path
) -> None:
    sumo_home = Path(__import__("sumo").SUMO_HOME)
    rilsa = sumo_home / "tools/sumolib/scenario/scenarios/RealWorld/RiLSA_example4/net.net.xml"
    before = kept_files(tmp_path)
    listed = client.get("/v1/networks").json()
    answer = client.post("/v1/networks?name=junction", content=rilsa.read_bytes())
    assert answer.status_code == 422
    assert answer.headers["content-type"] == "application/problem+json"
    assert "no loop of edges" in answer.json()["detail"]
    assert kept_files(tmp_path) == before
    assert client.get("/v1/networks").json() == listed
    assert client.get("/v1/networks/junction").status_code == 404


def test_other_content_under_a_known_name_is_a_conflict_that_keeps_no_file(
    client: TestClient, tmp_path: Path
) -> None:
    assert client.post("/v1/networks?name=town", content=PLAIN).status_code in (200, 201)
    before = kept_files(tmp_path)
    other = PLAIN + b"<!-- other content -->\n"
    answer = client.post("/v1/networks?name=town", content=other)
    assert answer.status_code == 409
    assert kept_files(tmp_path) == before
    # the same content again is still known, and its file is still there
    assert client.post("/v1/networks?name=town", content=PLAIN).status_code == 200
    assert kept_files(tmp_path) == before
