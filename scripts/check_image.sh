#!/usr/bin/env bash
# Checks what can be checked of docker/ without Docker:
#
#   1. the Dockerfile is multi-stage, runs as a non-root user and has a HEALTHCHECK;
#   2. in a fresh `python3 -m venv` in a temp dir, the build stage's install commands
#      (`pip install --upgrade pip`, `pip install .`) run on a copy of exactly what the
#      build stage COPYs (pyproject.toml, README.md, routing_svc/);
#   3. the runtime stage's build-time RUN (compiling the default network) runs in that venv;
#   4. the image's start command (ENTRYPOINT + CMD, with --host 127.0.0.1 and a free
#      port instead of 0.0.0.0:8000) starts with DATABASE_URL on a fresh PostgreSQL
#      database (SQLite if no server answers), the HEALTHCHECK one-liner (taken from the
#      Dockerfile, port substituted) is polled until it exits 0, then the server is
#      stopped with SIGTERM and must exit cleanly;
#   5. docker/compose.yaml parses as YAML and wires the service to PostgreSQL with
#      durable settings, and its service command is accepted by `routing-svc serve`.
#
# Usage: scripts/check_image.sh   (env: CHECK_IMAGE_PG_URL, default the local `test` db)
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
DOCKERFILE=docker/Dockerfile
COMPOSE=docker/compose.yaml
PG_ADMIN=${CHECK_IMAGE_PG_URL:-postgresql://postgres@127.0.0.1:5432/test}
PYTHON=${PYTHON:-python3}

TMP=$(mktemp -d)
SERVER_PID=
DB_NAME=
cleanup() {
  if [ -n "$SERVER_PID" ] && kill -0 "$SERVER_PID" 2>/dev/null; then
    kill -KILL "$SERVER_PID" 2>/dev/null || true
  fi
  if [ -n "$DB_NAME" ]; then
    psql "$PG_ADMIN" -qc "DROP DATABASE IF EXISTS \"$DB_NAME\" WITH (FORCE)" >/dev/null 2>&1 || true
  fi
  rm -rf "$TMP"
}
trap cleanup EXIT
step() { printf '== %s\n' "$*"; }
fail() { printf 'check_image: FAIL: %s\n' "$*" >&2; exit 1; }

# -- 1. static checks of the Dockerfile ------------------------------------------------
step "Dockerfile: stages, user, health check"
"$PYTHON" - "$DOCKERFILE" "$TMP" <<'EOF'
import json, re, shlex, sys
from pathlib import Path

text = Path(sys.argv[1]).read_text()
out = Path(sys.argv[2])
# join continuation lines, drop comments
lines, cur = [], ""
for raw in text.splitlines():
    if raw.lstrip().startswith("#"):
        continue
    cur += raw.rstrip("\\").rstrip() + " " if raw.rstrip().endswith("\\") else raw
    if not raw.rstrip().endswith("\\"):
        if cur.strip():
            lines.append(cur.strip())
        cur = ""
froms = [l for l in lines if l.upper().startswith("FROM ")]
assert len(froms) >= 2, "not multi-stage"
base = {l.split()[1] for l in froms}
assert all(b.startswith("python:3.11") for b in base), f"base images {base}"
stages = {}
stage = None
for l in lines:
    if l.upper().startswith("FROM "):
        stage = l.split()[-1]
        stages[stage] = []
    stages[stage].append(l)
build, runtime = list(stages)[0], list(stages)[-1]
users = [l.split()[1] for l in stages[runtime] if l.upper().startswith("USER ")]
assert users and users[-1] not in ("root", "0"), f"runtime stage runs as {users or 'root'}"
checks = [l for l in stages[runtime] if l.upper().startswith("HEALTHCHECK ")]
assert len(checks) == 1, "no HEALTHCHECK in the runtime stage"
hc = checks[0].split(" CMD ", 1)[1].strip()
copies = [l.split()[1:-1] for l in stages[build] if l.upper().startswith("COPY ") and "--from" not in l]
copied = [p for c in copies for p in c]
runs = [l[4:] for l in stages[build] if l.upper().startswith("RUN ")]
install = [c.strip() for r in runs for c in r.split("&&")]
assert any(re.search(r"pip install \.$", c) for c in install), f"no 'pip install .' in {install}"
rt_runs = [l[4:].strip() for l in stages[runtime] if l.upper().startswith("RUN ") and "apt-get" not in l and "useradd" not in l]
entry = json.loads(next(l[len("ENTRYPOINT"):] for l in stages[runtime] if l.upper().startswith("ENTRYPOINT ")))
cmd = json.loads(next(l[len("CMD"):] for l in stages[runtime] if l.upper().startswith("CMD ")))
(out / "copied").write_text("\n".join(copied) + "\n")
(out / "install").write_text("\n".join(c.replace("/opt/venv/bin/", "") for c in install if "pip " in c) + "\n")
(out / "healthcheck").write_text(hc + "\n")
(out / "build_runs").write_text("\n".join(rt_runs) + "\n")
(out / "start").write_text(json.dumps(entry + cmd))
print(f"stages: {', '.join(stages)}; runtime user: {users[-1]}")
print(f"build stage copies: {' '.join(copied)}")
print(f"install: {' && '.join(c for c in install if 'pip ' in c)}")
print(f"start: {shlex.join(entry + cmd)}")
print(f"healthcheck: {hc}")
EOF

# -- 2. fresh venv, the build stage's install ------------------------------------------
step "fresh venv: the build stage's install commands on a copy of what it COPYs"
mkdir -p "$TMP/src"
while read -r path; do
  [ -n "$path" ] || continue
  cp -r "$ROOT/$path" "$TMP/src/"
done <"$TMP/copied"
find "$TMP/src" -name __pycache__ -prune -exec rm -rf {} +
"$PYTHON" -m venv "$TMP/venv"
START=$(date +%s)
while read -r command; do
  [ -n "$command" ] || continue
  echo "   (cd src && $command)"
  (cd "$TMP/src" && PATH="$TMP/venv/bin:$PATH" PIP_NO_CACHE_DIR=1 bash -c "$command" >"$TMP/pip.log" 2>&1) \
    || { tail -30 "$TMP/pip.log"; fail "install command failed: $command"; }
done <"$TMP/install"
echo "   installed in $(( $(date +%s) - START ))s: $("$TMP/venv/bin/pip" show routing_svc | grep -E '^(Name|Version)' | tr '\n' ' ')"
mkdir -p "$TMP/home"
# run from outside the repository, so that the installed package is imported, not ./routing_svc
cd "$TMP/home"
"$TMP/venv/bin/python" - <<'EOF'
import routing_svc, pathlib
p = pathlib.Path(routing_svc.__file__).parent
assert "site-packages" in str(p), p
assert any((p / "store" / "migrations").rglob("*.py")), "migrations not installed"
assert (p / "service" / "static").is_dir(), "static files not installed"
print(f"   package at {p} (migrations and static files present)")
EOF

# -- 3. the runtime stage's build-time RUN ----------------------------------------------
step "runtime stage: build-time RUN (network compiled into ROUTING_SVC_CACHE)"
export ROUTING_SVC_CACHE="$TMP/home/.cache/routing_svc"
while read -r command; do
  [ -n "$command" ] || continue
  echo "   $command"
  (cd "$TMP/home" && PATH="$TMP/venv/bin:$PATH" bash -c "$command") || fail "build-time RUN failed"
done <"$TMP/build_runs"

# -- 4. start command + health check ------------------------------------------------------
PORT=$("$PYTHON" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
if psql "$PG_ADMIN" -qtAc 'SELECT 1' >/dev/null 2>&1; then
  DB_NAME="check_image_$$_$RANDOM"
  psql "$PG_ADMIN" -qc "CREATE DATABASE \"$DB_NAME\"" >/dev/null
  DATABASE_URL=$("$PYTHON" -c 'import sys; from sqlalchemy.engine import make_url; print(make_url(sys.argv[1]).set(drivername="postgresql+psycopg", database=sys.argv[2]).render_as_string(hide_password=False))' "$PG_ADMIN" "$DB_NAME")
else
  echo "   (no PostgreSQL at $PG_ADMIN: using SQLite)"
  DATABASE_URL="sqlite:///$TMP/home/var/routing_svc.db"
fi
export DATABASE_URL
mapfile -t START_CMD < <("$PYTHON" -c '
import json, sys
argv = json.load(open(sys.argv[1]))
argv[argv.index("--host") + 1] = "127.0.0.1"
argv[argv.index("--port") + 1] = sys.argv[2]
print("\n".join(argv))' "$TMP/start" "$PORT")
HEALTH=$(sed "s/127.0.0.1:8000/127.0.0.1:$PORT/" "$TMP/healthcheck")
step "start: DATABASE_URL=${DATABASE_URL%%\?*} ${START_CMD[*]}"
(cd "$TMP/home" && exec env PATH="$TMP/venv/bin:$PATH" "${START_CMD[@]}" >"$TMP/server.log" 2>&1) &
SERVER_PID=$!
step "poll the HEALTHCHECK command until healthy"
START=$(date +%s)
healthy=
for _ in $(seq 1 120); do
  kill -0 "$SERVER_PID" 2>/dev/null || { cat "$TMP/server.log"; fail "server exited during start-up"; }
  if (cd "$TMP/home" && PATH="$TMP/venv/bin:$PATH" bash -c "$HEALTH") 2>/dev/null; then
    healthy=1
    break
  fi
  sleep 0.5
done
[ -n "$healthy" ] || { cat "$TMP/server.log"; fail "not healthy after 60 s"; }
echo "   healthy after $(( $(date +%s) - START ))s: $(curl -s "http://127.0.0.1:$PORT/healthz" 2>/dev/null || true)"
step "stop (SIGTERM)"
kill -TERM "$SERVER_PID"
rc=0
wait "$SERVER_PID" || rc=$?
SERVER_PID=
# uvicorn re-raises the SIGTERM it handled once shutdown is complete: 143 = 128 + 15
case "$rc" in 0 | 143) ;; *) cat "$TMP/server.log"; fail "server exited with $rc on SIGTERM" ;; esac
grep -q "Application shutdown complete" "$TMP/server.log" \
  || { cat "$TMP/server.log"; fail "no graceful shutdown in the server log"; }
echo "   graceful shutdown (exit status $rc)"

# -- 5. compose.yaml --------------------------------------------------------------------------
step "compose.yaml: YAML, services, durable PostgreSQL, service command"
"$TMP/venv/bin/python" - "$ROOT/$COMPOSE" <<'EOF'
import sys
try:
    import yaml  # installed with uvicorn[standard]
except ImportError:
    print("   PyYAML is not installed: compose.yaml not parsed (skipped)")
    sys.exit(0)
from sqlalchemy.engine import make_url
from routing_svc.cli import build_parser

doc = yaml.safe_load(open(sys.argv[1]))
services = doc["services"]
assert {"service", "postgres"} <= set(services), set(services)
svc, pg = services["service"], services["postgres"]
url = make_url(svc["environment"]["DATABASE_URL"])
assert url.get_backend_name() == "postgresql" and url.host == "postgres", url
assert svc["depends_on"]["postgres"]["condition"] == "service_healthy"
assert svc["build"]["dockerfile"] == "docker/Dockerfile"
pg_cmd = " ".join(pg.get("command", []))
for setting in ("fsync", "synchronous_commit", "full_page_writes"):
    assert f"{setting}=off" not in pg_cmd, f"postgres runs with {setting}=off"
assert "healthcheck" in pg
args = build_parser("serve").parse_args(["serve", "--host", "0.0.0.0", "--port", "8000", *svc["command"]])
print(f"   services: {', '.join(services)}; DATABASE_URL -> {url.render_as_string()}; "
      f"service command accepted (workers={args.workers}, net={args.net}, no_demo={args.no_demo})")
EOF
step "OK"
