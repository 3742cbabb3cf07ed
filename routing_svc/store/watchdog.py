"""A client-side bound on every PostgreSQL connection the store's pool lends out.

The server-side timeouts (``statement_timeout``, ``lock_timeout``) only help
while the server hears the client, and TCP keepalives and
``tcp_user_timeout`` only while the peer of the socket is the server itself:
a proxy or load balancer in between (PgBouncer, HAProxy, a cloud proxy) keeps
acknowledging the client's packets while the database behind it is gone, and
a driver call then waits for an answer forever, holding its pool connection
and its thread.

:class:`ConnectionWatchdog` holds a deadline for each connection from the
moment the pool lends it out (before the liveness ping) until it comes back.
A thread shuts the socket of a connection whose deadline passed: the blocked
driver call then fails at once with a lost-connection error, SQLAlchemy
invalidates the connection, and both the thread and the pool slot are free
again.
"""

from __future__ import annotations

import contextlib
import os
import socket
import threading
import time
from typing import Any

from prometheus_client import Counter

__all__ = ["CONNECTIONS_CUT", "ConnectionWatchdog"]

CONNECTIONS_CUT = Counter(
    "routing_svc_db_connections_cut_total",
    "Database connections whose socket was shut because they were lent out past their bound",
)


class ConnectionWatchdog:
    """Shut the socket of any watched connection still lent out past its deadline.

    Parameters
    ----------
    name
        The thread's name.
    """

    def __init__(self, name: str = "routing-svc-db-watchdog") -> None:
        self._name = name
        self._watched: dict[int, tuple[float, Any]] = {}  # id(record) -> (deadline, dbapi)
        self._cond = threading.Condition()
        self._thread: threading.Thread | None = None
        self._stopped = False

    def watch(self, record: Any, dbapi_connection: Any, seconds: float) -> None:
        """Give the connection of pool record ``record`` ``seconds`` from now."""
        with self._cond:
            self._watched[id(record)] = (time.monotonic() + seconds, dbapi_connection)
            if self._thread is None and not self._stopped:
                self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
                self._thread.start()
            self._cond.notify()

    def release(self, record: Any) -> None:
        """The connection of ``record`` came back (or was dropped): stop watching it."""
        with self._cond:
            self._watched.pop(id(record), None)

    def stop(self) -> None:
        """Stop the thread (connections still watched are left alone)."""
        with self._cond:
            self._stopped = True
            self._watched.clear()
            self._cond.notify()
            thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join()

    def _run(self) -> None:
        with self._cond:
            while not self._stopped:
                now = time.monotonic()
                for key, (deadline, dbapi_connection) in list(self._watched.items()):
                    if deadline <= now:
                        del self._watched[key]
                        _shut(dbapi_connection)
                upcoming = min((d for d, _ in self._watched.values()), default=None)
                self._cond.wait(None if upcoming is None else max(0.0, upcoming - now))


def _shut(dbapi_connection: Any) -> None:
    """Shut down the socket of a psycopg connection (a closed one is left alone)."""
    with contextlib.suppress(Exception):
        fd = int(dbapi_connection.pgconn.socket)
        duplicate = socket.socket(fileno=os.dup(fd))
        try:
            duplicate.shutdown(socket.SHUT_RDWR)
        finally:
            duplicate.close()
        CONNECTIONS_CUT.inc()
