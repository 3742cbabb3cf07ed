"""The store's bounds on waits reach the database connection (PostgreSQL).

:class:`StoreTimeouts` sets libpq's TCP keepalives and ``tcp_user_timeout`` on
the socket, the server's statement, lock and idle-in-transaction timeouts on the
session (options in the URL win), and a watchdog shuts the socket of a
connection lent out past its bound, which frees both the caller and the pool.
"""

from __future__ import annotations

import os
import socket
import time
from typing import Any

import pytest
import sqlalchemy as sa

from routing_svc.store.engine import StoreTimeouts, create_store_engine
from routing_svc.store.watchdog import ConnectionWatchdog

BOUNDS = StoreTimeouts(
    connect_s=3,
    pool_checkout_s=1.0,
    statement_ms=1500,
    lock_ms=700,
    idle_in_transaction_ms=2500,
    lent_s=0.5,
    keepalives_idle_s=7,
    keepalives_interval_s=2,
    keepalives_count=4,
    tcp_user_timeout_ms=6000,
)


def _socket_option(dbapi_connection: Any, level: int, option: int) -> int:
    fd = int(dbapi_connection.pgconn.socket)
    duplicate = socket.socket(fileno=os.dup(fd))
    try:
        return int(duplicate.getsockopt(level, option))
    finally:
        duplicate.close()


def test_bounds_reach_the_socket_and_the_session(pg_url_with: Any) -> None:
    watchdog = ConnectionWatchdog()
    engine = create_store_engine(
        pg_url_with(""), busy_timeout_ms=0, timeouts=BOUNDS, watchdog=watchdog
    )
    try:
        with engine.connect() as conn:
            show = {
                name: conn.exec_driver_sql(f"SHOW {name}").scalar_one()
                for name in (
                    "statement_timeout",
                    "lock_timeout",
                    "idle_in_transaction_session_timeout",
                )
            }
            raw = conn.connection.dbapi_connection
            tcp = socket.IPPROTO_TCP
            options = {
                "keepalive": _socket_option(raw, socket.SOL_SOCKET, socket.SO_KEEPALIVE),
                "idle": _socket_option(raw, tcp, socket.TCP_KEEPIDLE),
                "interval": _socket_option(raw, tcp, socket.TCP_KEEPINTVL),
                "count": _socket_option(raw, tcp, socket.TCP_KEEPCNT),
                "user_timeout": _socket_option(raw, tcp, socket.TCP_USER_TIMEOUT),
            }
    finally:
        engine.dispose()
        watchdog.stop()
    assert show == {
        "statement_timeout": "1500ms",
        "lock_timeout": "700ms",
        "idle_in_transaction_session_timeout": "2500ms",
    }
    assert options == {"keepalive": 1, "idle": 7, "interval": 2, "count": 4, "user_timeout": 6000}


def test_options_in_the_url_win(pg_url_with: Any) -> None:
    engine = create_store_engine(
        pg_url_with("-c statement_timeout=9s"), busy_timeout_ms=0, timeouts=BOUNDS
    )
    try:
        with engine.connect() as conn:
            assert conn.exec_driver_sql("SHOW statement_timeout").scalar_one() == "9s"
            assert conn.exec_driver_sql("SHOW lock_timeout").scalar_one() == "700ms"
    finally:
        engine.dispose()


def test_a_connection_lent_past_its_bound_is_cut_and_comes_back(pg_url_with: Any) -> None:
    # the server would let the statement run for 60 s: only the client's bound ends it
    watchdog = ConnectionWatchdog()
    engine = create_store_engine(
        pg_url_with("-c statement_timeout=60s"),
        busy_timeout_ms=0,
        timeouts=BOUNDS,
        watchdog=watchdog,
    )
    pool: Any = engine.pool
    try:
        t0 = time.monotonic()
        with pytest.raises(sa.exc.OperationalError) as raised, engine.connect() as conn:
            conn.execute(sa.text("SELECT pg_sleep(30)"))
        took = time.monotonic() - t0
        assert raised.value.connection_invalidated
        assert took < 0.5 + 2.0
        assert pool.checkedout() == 0
        with engine.connect() as conn:  # a fresh connection serves the next caller
            assert conn.execute(sa.text("SELECT 1")).scalar_one() == 1
        assert pool.checkedout() == 0
    finally:
        engine.dispose()
        watchdog.stop()
