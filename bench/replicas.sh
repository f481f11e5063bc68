#!/usr/bin/env bash
# Replicas on loopback (docs/service/stores.md): jobs per second and latency with 1, 2 and 3
# radiosity-server replicas sharing a throwaway PostgreSQL and blob directory, against one server
# on SQLite; and the store's own cost per job on each backend.
#
#   bash bench/replicas.sh [SECONDS] [BUILD_DIR]      (defaults: 20, build)
#
# PostgreSQL (Debian's postgresql package) runs from a temporary directory on a Unix socket,
# as `nobody` when run as root; everything is removed at the end.
set -euo pipefail
seconds="${1:-20}"
build="$(cd "${2:-build}" && pwd)"
bin="$build/bin"
pgbin="$(ls -d /usr/lib/postgresql/*/bin | sort -V | tail -1)"
work="$(mktemp -d /tmp/radiosity-replicas-XXXXXX)"
chmod 755 "$work"
as=()
if [ "$(id -u)" = 0 ]; then
  chown nobody "$work"
  as=(runuser -u nobody --)
fi
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  "${as[@]}" "$pgbin/pg_ctl" -D "$work/pg" -m immediate stop >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
"${as[@]}" "$pgbin/initdb" -D "$work/pg" -A trust -U radiosity >/dev/null
"${as[@]}" "$pgbin/pg_ctl" -D "$work/pg" -l "$work/pg.log" -w \
  -o "-k $work -c listen_addresses='' -c max_connections=200" start >/dev/null
uri="postgresql:///postgres?host=$work&user=radiosity"

echo "== the store's cost per job"
mkdir -p "$work/sqlite-cost"
"$bin/radiosity-loadtest" --store-cost "sqlite:$work/sqlite-cost" --store-jobs 1000
"$bin/radiosity-loadtest" --store-cost "$uri" --store-jobs 1000

load() {  # load LABEL ADDRESSES...
  echo "== $1"
  shift
  "$bin/radiosity-loadtest" --servers "$(IFS=,; echo "$*")" --seconds "$seconds" --clients 4 \
    --inflight 2 --watchers 2 --max-rays 100000 --max-elements 200 --grace 120 |
    grep -E "^(jobs|throughput|latency submit->done, server|watch|result)"
}
address=""
start() {  # start NAME ARGS...: a server on a free port, its address in $address
  local name="$1"
  shift
  "$bin/radiosity-server" --listen 127.0.0.1:0 --port-file "$work/$name.port" \
    --data-dir "$work/$name" --threads-per-job 1 --max-queued 1000 "$@" \
    2>"$work/$name.log" >/dev/null &
  pids+=($!)
  for _ in $(seq 100); do [ -s "$work/$name.port" ] && break; sleep 0.1; done
  if [ ! -s "$work/$name.port" ]; then
    cat "$work/$name.log" >&2
    exit 1
  fi
  address="127.0.0.1:$(cat "$work/$name.port")"
}
stop_all() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  pids=()
}

start single-1 --workers 1
load "one server, SQLite, 1 worker" "$address"
stop_all
start single-2 --workers 2
load "one server, SQLite, 2 workers" "$address"
stop_all
for n in 1 2 3; do
  "$pgbin/psql" -h "$work" -U radiosity -d postgres -qc "DROP DATABASE IF EXISTS r$n" \
    -c "CREATE DATABASE r$n" >/dev/null
  addresses=()
  for i in $(seq "$n"); do
    start "r$n-$i" --workers 1 --store "postgresql:///r$n?host=$work&user=radiosity" \
      --blob-dir "$work/blobs-$n"
    addresses+=("$address")
  done
  load "$n replica(s), PostgreSQL, 1 worker each" "${addresses[@]}"
  stop_all
done
