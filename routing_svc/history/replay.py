"""Replaying a checked history through the service, in time order, in keyed chunks.

The calls are sorted by time (a stable sort: calls at the same time keep their
file order) and sent as ``POST /v1/fleets/{id}/targets:batch`` bodies of
``chunk_size`` targets. Each chunk is one transaction of the service's write
path (applied whole or not at all) and carries the ``Idempotency-Key``
``history:<sha256 of the file>:<chunk size>:<chunk index>``: after a crash, the
same command sends the same chunks with the same keys, and the service answers
the chunks it already applied from its log, applying nothing twice.

Two clients speak the route: :class:`InProcessHistoryClient` calls the
service's domain code on a database directly (positions resolved as the route
resolves them, the same request digest), :class:`HttpHistoryClient` a running server.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
import orjson
from tqdm import tqdm

from routing_svc.client import FleetClient, HttpFleetClient
from routing_svc.errors import InvalidInput, RoutingSvcError
from routing_svc.history.calls import BadRow, CallTable
from routing_svc.history.places import PlacedCalls
from routing_svc.long_lived import frozen_heap
from routing_svc.service.canonical import result_cost
from routing_svc.service.inprocess import InProcessFleetClient
from routing_svc.service.schemas import TargetBatch, edge_target

MAX_CHUNK: int = next(
    m.max_length for m in TargetBatch.model_fields["targets"].metadata if hasattr(m, "max_length")
)
"""The batch route's limit on targets per request."""
DEFAULT_CHUNK = 2_000


@dataclass
class CallChunk:
    """Calls sent in one request: edge, offset and required types (or ``None``) each."""

    edges: list[str]
    offsets: list[float]
    requires: list[tuple[str, ...] | None]

    def targets(self) -> list[dict[str, Any]]:
        """The batch route's ``targets``, as validated."""
        return [
            edge_target(e, o, r)
            for e, o, r in zip(self.edges, self.offsets, self.requires, strict=True)
        ]


@dataclass
class ChunkAnswer:
    """What a replay keeps of a chunk's answer: each call's cost, the first call's
    event number, and the fleet's version after the chunk."""

    costs: list[float]
    first_seq: int
    version: int


class HistoryClient(FleetClient, Protocol):
    """A fleet client that can also post a batch of targets."""

    def close(self) -> None: ...

    def post_batch(
        self, fleet_id: str, targets: list[dict[str, Any]], *, idempotency_key: str
    ) -> tuple[list[dict[str, Any]], int]:
        """Each target's result and the version after the batch."""
        ...

    def post_chunk(self, fleet_id: str, chunk: CallChunk, *, idempotency_key: str) -> ChunkAnswer:
        """``post_batch`` of the chunk's calls, answered with what a replay keeps."""
        ...


class InProcessHistoryClient(InProcessFleetClient):
    """The in-process client with the batch route's domain call."""

    def __enter__(self) -> InProcessHistoryClient:
        return self

    def post_chunk(self, fleet_id: str, chunk: CallChunk, *, idempotency_key: str) -> ChunkAnswer:
        """The batch route's domain call on calls placed on the fleet's network already
        (:func:`~routing_svc.history.places.place_locally`): positions resolved as the
        route resolves them, the same request digest, and only the costs read back."""
        if not 1 <= len(chunk.edges) <= MAX_CHUNK:
            raise InvalidInput(f"a chunk holds 1 to {MAX_CHUNK} calls, got {len(chunk.edges)}")
        entry = self.service.network_of(fleet_id)
        resolved = [
            (entry.resolve_edge(e, o), list(r) if r else None)  # as the route's targets
            for e, o, r in zip(chunk.edges, chunk.offsets, chunk.requires, strict=True)
        ]
        results, version = self.service.submit_resolved(
            fleet_id,
            resolved,
            idempotency_key=idempotency_key,
            body={"targets": chunk.targets()},
        ).result()
        first_seq = int(orjson.loads(results[0])["seq"])
        return ChunkAnswer([result_cost(r) for r in results], first_seq, version)

    def post_batch(
        self, fleet_id: str, targets: list[dict[str, Any]], *, idempotency_key: str
    ) -> tuple[list[dict[str, Any]], int]:
        batch = TargetBatch.model_validate({"targets": targets})
        results, version = self.service.post_targets(
            fleet_id,
            batch.targets,
            idempotency_key=idempotency_key,
            body=batch.model_dump(mode="json"),
        )
        return orjson.loads("[" + ",".join(results) + "]"), version


class HttpHistoryClient(HttpFleetClient):
    """The HTTP client with ``POST /v1/fleets/{id}/targets:batch``."""

    def post_batch(
        self, fleet_id: str, targets: list[dict[str, Any]], *, idempotency_key: str
    ) -> tuple[list[dict[str, Any]], int]:
        answer = self._json(
            self._send(
                "POST",
                f"/v1/fleets/{fleet_id}/targets:batch",
                json={"targets": targets},
                headers={"Idempotency-Key": idempotency_key},
            )
        )
        return list(answer["results"]), int(answer["version"])

    def post_chunk(self, fleet_id: str, chunk: CallChunk, *, idempotency_key: str) -> ChunkAnswer:
        results, version = self.post_batch(
            fleet_id, chunk.targets(), idempotency_key=idempotency_key
        )
        return ChunkAnswer([float(r["cost"]) for r in results], int(results[0]["seq"]), version)

    def resolve_positions(self, network_id: str, positions: list[dict[str, Any]]) -> dict[str, Any]:
        """``POST /v1/networks/{id}/positions:resolve``: each position on the network, or
        why not."""
        return self._json(
            self._send(
                "POST",
                f"/v1/networks/{network_id}/positions:resolve",
                json={"positions": positions},
                write=False,
            )
        )


class HistoryRefused(InvalidInput):
    """The history has bad rows and ``--on-bad-row refuse``: nothing was sent."""

    def __init__(self, bad: Sequence[BadRow]) -> None:
        shown = "; ".join(f"line {r.line}: {r.reason}" for r in bad[:20])
        more = f"; ... ({len(bad) - 20} more)" if len(bad) > 20 else ""
        super().__init__(f"{len(bad)} bad row(s), nothing was imported: {shown}{more}")
        self.bad = list(bad)


class HistoryInterrupted(RoutingSvcError):
    """A chunk failed part-way through a replay; the chunks before it are applied.

    Each chunk carries its key (:func:`chunk_key`), so the same command again applies
    every call once."""

    title = "Import interrupted"

    def __init__(self, index: int, chunks: int, cause: RoutingSvcError) -> None:
        done = "no chunk is" if index == 0 else f"chunks 1 to {index} are"
        super().__init__(
            f"chunk {index + 1} of {chunks} failed ({cause.title.lower()}: {cause.detail}); "
            f"{done} applied, and the same command again applies each call once"
        )
        self.cause = cause


@dataclass
class Checkpoint:
    """The fleet's reference positions after ``calls`` calls of the replay."""

    calls: int
    version: int
    positions: list[dict[str, Any]]


@dataclass
class ImportResult:
    """What a replay did, with what the report needs.

    ``order`` indexes the :class:`CallTable` rows in the order sent; ``costs`` is
    each sent call's cost from its serving vehicle(s), in that order.
    """

    fleet: str
    sha256: str
    chunk_size: int
    chunks: int
    applied_chunks: int
    sent: int
    applied: int
    bad: list[BadRow]
    version_before: int
    version_after: int
    seconds: float
    order: npt.NDArray[np.int64]
    costs: npt.NDArray[np.float64]
    checkpoints: list[Checkpoint] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        return {
            "fleet": self.fleet,
            "file_sha256": self.sha256,
            "calls_sent": self.sent,
            "calls_applied": self.applied,
            "calls_already_applied": self.sent - self.applied,
            "chunks": self.chunks,
            "chunks_applied": self.applied_chunks,
            "chunk_size": self.chunk_size,
            "bad_rows": [r.to_dict() for r in self.bad],
            "version_before": self.version_before,
            "version_after": self.version_after,
            "seconds": self.seconds,
            "calls_per_second": self.sent / self.seconds if self.seconds > 0 else None,
        }


def chunk_key(sha256: str, chunk_size: int, index: int) -> str:
    """The ``Idempotency-Key`` of chunk ``index`` of the file with digest ``sha256``."""
    return f"history:{sha256}:{chunk_size}:{index}"


def time_order(table: CallTable, placed: PlacedCalls) -> npt.NDArray[np.int64]:
    """Positions in ``placed`` of the sendable calls, sorted by time (stable)."""
    return np.argsort(table.seconds[placed.rows], kind="stable").astype(np.int64)


def _positions(fleet: dict[str, Any]) -> list[dict[str, Any]]:
    return [
        {"id": v["id"], "edge": v["position"]["edge"], "offset": v["position"]["offset"]}
        for v in fleet["vehicles"]
    ]


def replay_history(
    table: CallTable,
    placed: PlacedCalls,
    client: HistoryClient,
    fleet_id: str,
    *,
    on_bad_row: str = "refuse",
    chunk_size: int = DEFAULT_CHUNK,
    checkpoints: int = 20,
    progress: bool = True,
) -> ImportResult:
    """Send the history's calls in time order, chunk by chunk.

    Parameters
    ----------
    on_bad_row
        ``refuse``: any bad row raises :class:`HistoryRefused` before anything
        is sent; ``skip``: the bad rows are left out (and listed in the result).
    chunk_size
        Targets per request, 1 to the route's limit :data:`MAX_CHUNK`.
    checkpoints
        About how many times the fleet's reference positions are read during the
        replay (besides before and after it), for the report's gap curve.
    """
    if on_bad_row not in ("refuse", "skip"):
        raise InvalidInput(f"on_bad_row must be 'refuse' or 'skip', got {on_bad_row!r}")
    if not 1 <= chunk_size <= MAX_CHUNK:
        raise InvalidInput(f"the chunk size must be 1 to {MAX_CHUNK}, got {chunk_size}")
    if placed.bad and on_bad_row == "refuse":
        raise HistoryRefused(placed.bad)
    if placed.rows.shape[0] == 0:
        raise InvalidInput("the history has no call to import")
    order = time_order(table, placed)
    before = client.get_fleet(fleet_id)
    marks: list[Checkpoint] = [Checkpoint(0, int(before["version"]), _positions(before))]
    n = order.shape[0]
    chunks = -(-n // chunk_size)
    every = max(1, chunks // max(checkpoints, 1))
    costs = np.empty(n, dtype=np.float64)
    applied = applied_chunks = 0
    version = int(before["version"])
    started = time.perf_counter()
    with frozen_heap(), tqdm(total=n, disable=not progress, file=sys.stderr, unit="call") as bar:
        for index in range(chunks):
            part = order[index * chunk_size : (index + 1) * chunk_size].tolist()
            chunk = CallChunk(
                [placed.edges[i] for i in part],
                [placed.offsets[i] for i in part],
                [table.requires[r] for r in placed.rows[part].tolist()],
            )
            key = chunk_key(table.sha256, chunk_size, index)
            try:
                answer = client.post_chunk(fleet_id, chunk, idempotency_key=key)
            except RoutingSvcError as exc:
                raise HistoryInterrupted(index, chunks, exc) from exc
            version = answer.version
            costs[index * chunk_size : index * chunk_size + len(answer.costs)] = answer.costs
            if answer.first_seq > int(before["version"]):
                applied += len(answer.costs)
                applied_chunks += 1
            bar.update(len(part))
            if (index + 1) % every == 0 and index + 1 < chunks:
                marks.append(
                    Checkpoint(
                        index * chunk_size + len(part),
                        version,
                        _positions(client.get_fleet(fleet_id)),
                    )
                )
    seconds = time.perf_counter() - started
    after = client.get_fleet(fleet_id)
    marks.append(Checkpoint(n, int(after["version"]), _positions(after)))
    return ImportResult(
        fleet=fleet_id,
        sha256=table.sha256,
        chunk_size=chunk_size,
        chunks=chunks,
        applied_chunks=applied_chunks,
        sent=n,
        applied=applied,
        bad=placed.bad,
        version_before=int(before["version"]),
        version_after=int(after["version"]),
        seconds=seconds,
        order=placed.rows[order],
        costs=costs,
        checkpoints=marks,
    )
