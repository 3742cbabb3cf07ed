"""The write path: how a request's events become durable and its answer comes back.

- :mod:`~routing_svc.service.write_path.group_commit`: :class:`GroupCommit`, the
  queues and writers that commit many requests in one transaction;
- :mod:`~routing_svc.service.write_path.pending`: one queued request and its
  :data:`PendingAnswer`;
- :mod:`~routing_svc.service.write_path.committer`: the thread that runs the event
  loop's commits.

The rows of a group are staged by :mod:`routing_svc.store.staging`. The way of a
target from socket to ``fsync`` to answer is drawn in ``docs/write_path.md``.
"""

from routing_svc.service.write_path.group_commit import SNAPSHOT_EVERY, FleetRuntimes, GroupCommit
from routing_svc.service.write_path.pending import GROUP_CAP, Answer, Compute, PendingAnswer

__all__ = [
    "GROUP_CAP",
    "SNAPSHOT_EVERY",
    "Answer",
    "Compute",
    "FleetRuntimes",
    "GroupCommit",
    "PendingAnswer",
]
