"""The exception tree of routing_svc.

::

    RoutingSvcError
    ├── InvalidInput            bad values (NaN, inf, negative speeds, bad options)
    │   └── UnmetRequirement    a target needs types the fleet cannot provide
    ├── NotFound
    │   ├── UnknownFleet
    │   ├── UnknownNetwork
    │   ├── UnknownEdge
    │   └── UnknownVehicleType
    ├── Unreachable             a target that no vehicle can reach
    ├── OffNetwork              a coordinate too far from any usable edge
    ├── InvalidNetwork          a network file that cannot be used (malformed, hostile, empty)
    │   └── XmlLimitExceeded    XML past one of the screen's limits (names the limit)
    ├── Conflict                an id that already exists, an idempotency key reused for other input
    ├── PayloadTooLarge         a body or a decompressed file beyond the configured limit
    ├── StorageError            the store refused or failed to work (unsafe durability
    │   │                       settings, unreachable, full, a driver error)
    │   ├── StorageTimeout      a wait on the store passed its bound; nothing was written
    │   └── CommitOutcomeUnknown  a write may or may not have committed
    ├── ReplayMismatch          a replay of the event log disagrees with the stored state
    └── ServiceUnreachable      a client's request got no answer (refused, broken, timed out)

Every layer raises these; the service maps each class to one HTTP status in one place.
"""

from __future__ import annotations


class RoutingSvcError(Exception):
    """Base class of every error that routing_svc raises on purpose."""

    title = "Routing service error"

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail

    def problem_members(self) -> dict[str, object]:
        """Extension members of this error's problem+json body (RFC 9457, section 3.2)."""
        return {}


class InvalidInput(RoutingSvcError):
    title = "Invalid input"


class UnmetRequirement(InvalidInput):
    title = "Requirement cannot be met"


class NotFound(RoutingSvcError):
    title = "Not found"


class UnknownFleet(NotFound):
    title = "Unknown fleet"


class UnknownNetwork(NotFound):
    title = "Unknown network"


class UnknownEdge(NotFound):
    title = "Unknown edge"


class UnknownVehicleType(NotFound):
    title = "Unknown vehicle type"


class Unreachable(RoutingSvcError):
    title = "Target unreachable"


class OffNetwork(RoutingSvcError):
    title = "Position off the network"


class InvalidNetwork(RoutingSvcError):
    title = "Invalid network"


class XmlLimitExceeded(InvalidNetwork):
    """An XML document past one of the limits of :mod:`routing_svc.network.xml_limits`.

    Parameters
    ----------
    detail : str
        What was found, in words.
    limit : str
        The name of the limit's constant, e.g. ``"MAX_ATTRIBUTE_BYTES"``.
    maximum : int
        The limit's value for this document.
    """

    title = "XML limit exceeded"

    def __init__(self, detail: str, *, limit: str, maximum: int) -> None:
        super().__init__(detail)
        self.limit = limit
        self.maximum = maximum

    def problem_members(self) -> dict[str, object]:
        return {"limit": self.limit, "maximum": self.maximum}


class Conflict(RoutingSvcError):
    title = "Conflict"


class PayloadTooLarge(RoutingSvcError):
    title = "Payload too large"


class StorageError(RoutingSvcError):
    title = "Storage error"


class StorageTimeout(StorageError):
    title = "Storage timeout"


class CommitOutcomeUnknown(StorageError):
    """The connection was lost, or the request's deadline passed, while a write was
    being committed: it may have been. A retry with the same ``Idempotency-Key``
    settles it (applied once, or answered from the log); a fleet's creation, which
    takes no key, is settled by its id (created now, or a conflict)."""

    title = "Commit outcome unknown"


class ReplayMismatch(RoutingSvcError):
    title = "Replay mismatch"


class ServiceUnreachable(RoutingSvcError):
    """Raised by the HTTP client (:class:`routing_svc.client.HttpFleetClient`), never by
    the service: the connection was refused or broke, or no answer came in time."""

    title = "Service unreachable"
