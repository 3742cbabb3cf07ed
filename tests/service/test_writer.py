"""The service's writer: requests of several fleets share one transaction, and a
fleet that fails cannot fail another's requests (SQLite and PostgreSQL)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa

from routing_svc.errors import UnknownFleet
from routing_svc.service.fleets import FleetService
from routing_svc.service.inprocess import InProcessFleetClient
from routing_svc.service.schemas import TargetSpec
from tests.helpers import DRT, fleet_body, targets


@pytest.fixture
def client(db_url: str) -> Iterator[InProcessFleetClient]:
    with InProcessFleetClient(database_url=db_url) as opened:
        opened.add_network(Path(DRT), name="drt")
        for fleet_id in ("a", "b", "c"):
            opened.create_fleet(fleet_body(fleet_id))
        yield opened


def specs(seed: int, n: int) -> list[TargetSpec]:
    return [TargetSpec.model_validate(t) for t in targets(seed, n)]


def commits_of(service: FleetService) -> list[int]:
    seen: list[int] = []
    sa.event.listen(service.log.engine, "commit", lambda conn: seen.append(1))
    return seen


def submit_together(service: FleetService, work: list[tuple[str, list[TargetSpec]]]) -> list[Any]:
    """Queue every request while the writer cannot take any, so that it takes them
    as one batch."""
    with service.group_commit.together():
        return [service.submit_targets(fleet_id, batch) for fleet_id, batch in work]


def test_fleets_share_one_commit(client: InProcessFleetClient) -> None:
    service = client.service
    work = [("a", specs(1, 2)), ("b", specs(2, 1)), ("a", specs(3, 1)), ("c", specs(4, 3))]
    commits = commits_of(service)
    futures = submit_together(service, work)
    answers = [f.result(timeout=60) for f in futures]
    assert len(commits) == 1
    assert [version for _, version in answers] == [3, 2, 4, 4]
    assert [len(results) for results, _ in answers] == [2, 1, 1, 3]
    # the same targets applied serially to fresh fleets give the same events
    with InProcessFleetClient() as serial:
        serial.add_network(Path(DRT), name="drt")
        for fleet_id in ("a", "b", "c"):
            serial.create_fleet(fleet_body(fleet_id))
        for fleet_id, batch in work:
            serial.service.post_targets(fleet_id, batch)
        for fleet_id in ("a", "b", "c"):
            assert strip(serial.service.events(fleet_id, after=0, limit=100)) == strip(
                service.events(fleet_id, after=0, limit=100)
            )


def strip(events: list[dict[str, Any]]) -> list[tuple[int, str, Any, Any]]:
    return [(e["seq"], e["kind"], e["payload"], e["result"]) for e in events]


def test_a_failing_fleet_does_not_fail_the_others(client: InProcessFleetClient) -> None:
    service = client.service
    service.get_fleet("b")  # cached here ...
    other = FleetService(service.log, service.networks, recent_window=10)
    other.delete_fleet("b")  # ... and deleted by another instance
    futures = submit_together(service, [("a", specs(5, 1)), ("b", specs(6, 1)), ("c", specs(7, 1))])
    assert futures[0].result(timeout=60)[1] == 2
    with pytest.raises(UnknownFleet):
        futures[1].result(timeout=60)
    assert futures[2].result(timeout=60)[1] == 2
    assert [len(service.events(f, after=0, limit=10)) for f in ("a", "c")] == [2, 2]
    assert service.log.integrity_check() == []


def test_close_commits_what_is_queued(db_url: str) -> None:
    client = InProcessFleetClient(database_url=db_url)
    client.add_network(Path(DRT), name="drt")
    client.create_fleet(fleet_body("a"))
    service = client.service
    futures = submit_together(service, [("a", specs(8, 1)), ("a", specs(9, 2))])
    service.close()
    assert [f.result(timeout=0)[1] for f in futures] == [2, 4]
    with pytest.raises(Exception, match="shut down"):
        service.submit_targets("a", specs(10, 1))
    client.close()
