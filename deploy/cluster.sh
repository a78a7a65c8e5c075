#!/usr/bin/env bash
# A local navguard cluster in one command: Postgres, NATS, N navguard nodes and
# HAProxy in front of them, on loopback ports, everything under one directory.
# See docs/deployment.md, and `deploy/cluster.sh --help`.
set -euo pipefail

SCRIPT_DIR=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
REPO_ROOT=$(cd "$SCRIPT_DIR/.." && pwd)
HAPROXY_TEMPLATE="$SCRIPT_DIR/haproxy.cfg"
NATS_TEMPLATE="$SCRIPT_DIR/nats.conf"
# The NATS user every node logs in as (deploy/nats.conf).
NATS_USER=navguard-node

# Seconds a component has to come up, and a node to finish draining.
START_TIMEOUT_S=${NG_START_TIMEOUT_S:-30}
DRAIN_TIMEOUT_S=${NG_DRAIN_TIMEOUT_S:-60}
# The node's flags after --bind and --db. @NATS_URL@, @NODE_ID@, @NODE_URL@ and
# @LEASE_MS@ are replaced per node. NG_NODE_FLAGS, when set (even to ""), replaces
# this template: NG_NODE_FLAGS="" starts nodes with --bind and --db only.
DEFAULT_NODE_FLAGS='--nats @NATS_URL@ --node-id @NODE_ID@ --advertise @NODE_URL@ --lease-ms @LEASE_MS@ --checkpoint-ms 1000 --drain-wait-ms 1500'

usage() {
  cat <<'EOF'
Usage: deploy/cluster.sh COMMAND [OPTIONS]

A local navguard cluster: Postgres, NATS, N navguard nodes, HAProxy in front.
Ports, from the base P: HAProxy P (HTTP) and P+13 (TLS), nodes P+1..P+N, NATS
P+10 (monitoring P+11), HAProxy stats P+12, Postgres P+20. All on 127.0.0.1.

Secured like a production cluster (docs/deployment.md, Securing a cluster): a
test CA and a certificate for 127.0.0.1 in DIR/tls (openssl), used by NATS
(TLS required), Postgres (TLS, scram-sha-256 passwords; the nodes connect with
sslmode=verify-full) and HAProxy's TLS frontend; a NATS password, a Postgres
password and a cluster key (every bus message signed) in DIR/secrets, mode 0600.

Commands:
  start [--dir DIR] [--port-base P] [--nodes N] [--bin PATH] [--pg-url URL]
        [--lease-ms MS] [--token T]
            Start Postgres (a throw-away cluster in DIR/pg, unless --pg-url or
            NAVGUARD_PG_URL names a running server), NATS, N nodes (default 3,
            at most 9) and HAProxy; wait until each is up; write DIR/cluster.env.
  stop [--dir DIR] [--purge]
            SIGTERM the nodes and wait for them to drain, then stop HAProxy,
            NATS and Postgres (pg_ctl stop -m fast). Keeps DIR (data, logs,
            cluster.env) and removes only the pid files, unless --purge (then
            removes DIR).
  status [--dir DIR]
            One line per component: up/down, pid, URL (nodes: /healthz status
            and HAProxy's view). Exit status 0 if everything is up, 3 if not.
            NATS is the nats-server listening on its port, so one restarted
            by hand is reported (and stopped by stop) too.
  kill K [--dir DIR]
            kill -9 node K (the crash test).
  drain K [--dir DIR]
            SIGTERM node K and wait until it exits; print how long it took.
  restart K [--dir DIR]
            Start node K again with the flags it had; wait until HAProxy sees it.
  add [--dir DIR]
            Start node N+1, add it to HAProxy's config and reload HAProxy
            (haproxy -sf: open connections are not cut).
  --help    This text.

Defaults: DIR=${TMPDIR:-/tmp}/navguard-cluster, P=18080, N=3, --lease-ms 3000,
--bin: target/release/navguard if it exists, else target/debug/navguard, else
`cargo build --release` first. --token (or NAVGUARD_TOKEN) is passed to the
nodes as NAVGUARD_TOKEN.

Environment:
  NG_NODE_FLAGS        the nodes' flags after --bind and --db (default: the
                       cluster flags --nats … --node-id nodeK --advertise …
                       --lease-ms … --checkpoint-ms 1000 --drain-wait-ms 1500;
                       @NATS_URL@ @NODE_ID@ @NODE_URL@ @LEASE_MS@ are replaced)
  NAVGUARD_PG_URL      like --pg-url
  NG_PG_TRUST          1: the Postgres this script starts trusts every connection
                       from 127.0.0.1 (no password, no TLS): throw-away clusters
                       only
  NG_START_TIMEOUT_S   seconds a component has to come up (30)
  NG_DRAIN_TIMEOUT_S   seconds `drain` and `stop` wait for a node (60)

Needs bash, curl, openssl, and the Debian packages postgresql (unless --pg-url; then
postgresql-client for pg_isready), nats-server and haproxy. As root, Postgres
runs as the user nobody.
EOF
}

die() {
  echo "cluster.sh: $*" >&2
  exit 1
}

now_ms() { date +%s%3N; }

# Seconds since a now_ms() value, with two decimals.
since_s() {
  local ms
  ms=$(($(now_ms) - $1))
  printf '%d.%02d' $((ms / 1000)) $((ms % 1000 / 10))
}

# A value single-quoted for the shell.
shq() {
  local s=${1//\'/\'\\\'\'}
  printf "'%s'" "$s"
}

need() {
  local cmd=$1 pkg=$2
  command -v "$cmd" >/dev/null 2>&1 || die "$cmd not found: install the Debian package $pkg (apt-get install $pkg)"
}

# The HTTP status of a GET, or 000 when nothing answers.
http_code() {
  curl -s -o /dev/null -m 2 -w '%{http_code}' "$1" 2>/dev/null || true
}

# Whether a pid is a live process (not a zombie).
alive() {
  local pid=${1:-} stat
  [ -n "$pid" ] || return 1
  kill -0 "$pid" 2>/dev/null || return 1
  stat=$(cat "/proc/$pid/stat" 2>/dev/null) || return 0
  stat=${stat##*') '}
  [ "${stat%% *}" != Z ]
}

# Whether something listens on 127.0.0.1:PORT.
listening() {
  (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null
}

port_must_be_free() {
  if listening "$1"; then
    die "port $1 ($2) is already in use on 127.0.0.1: stop what listens there (ss -ltnp 'sport = :$1') or choose another --port-base"
  fi
}

tail_log() {
  local log=$1
  if [ -s "$log" ]; then
    echo "--- last lines of $log:" >&2
    tail -n 25 "$log" >&2
    echo "---" >&2
  else
    echo "($log is empty or missing)" >&2
  fi
}

# ---------------------------------------------------------------- state

# Paths and ports derived from DIR and P.
derive() {
  RUN="$DIR/run"
  LB_PORT=$PORT_BASE
  NATS_PORT=$((PORT_BASE + 10))
  NATS_MON_PORT=$((PORT_BASE + 11))
  STATS_PORT=$((PORT_BASE + 12))
  PG_PORT=$((PORT_BASE + 20))
  LB_TLS_PORT=$((PORT_BASE + 13))
  LB_URL="http://127.0.0.1:$LB_PORT"
  LB_TLS_URL="https://127.0.0.1:$LB_TLS_PORT"
  NATS_URL="tls://127.0.0.1:$NATS_PORT"
  TLS_DIR="$DIR/tls"
  SECRETS="$DIR/secrets"
  NATS_MONITOR_URL="http://127.0.0.1:$NATS_MON_PORT"
  HAPROXY_STATS_URL="http://127.0.0.1:$STATS_PORT/"
}

node_port() { echo $((PORT_BASE + $1)); }
node_url() { echo "http://127.0.0.1:$(node_port "$1")"; }
pid_of() { cat "$RUN/$1.pid" 2>/dev/null || true; }

pg_pid() {
  if [ "$PG_OWNED" = 1 ]; then
    head -n 1 "$DIR/pg/data/postmaster.pid" 2>/dev/null || true
  fi
}

# Writes DIR/cluster.env: what clients and tests need, then what this script
# needs to stop, restart and add nodes later (NG_*).
write_env() {
  local k pid tmp="$DIR/cluster.env.tmp"
  (
    umask 077
    {
      echo "# Written by deploy/cluster.sh; source it: . $(shq "$DIR/cluster.env")"
      echo "LB_URL=$(shq "$LB_URL")"
      echo "LB_TLS_URL=$(shq "$LB_TLS_URL")"
      echo "TLS_CA=$(shq "$TLS_DIR/ca.pem")"
      echo "NODES=$NODES"
      for k in $(seq 1 "$NODES"); do
        pid=$(pid_of "node$k")
        alive "$pid" || pid=""
        echo "NODE${k}_URL=$(shq "$(node_url "$k")")"
        echo "NODE${k}_PID=$(shq "$pid")"
      done
      echo "PG_URL=$(shq "$PG_URL")"
      echo "NATS_URL=$(shq "$NATS_URL")"
      echo "NATS_CONF=$(shq "$DIR/nats.conf")"
      echo "NATS_USER=$(shq "$NATS_USER")"
      echo "NATS_PASSWORD_FILE=$(shq "$SECRETS/nats-password")"
      echo "CLUSTER_KEY_FILE=$(shq "$SECRETS/cluster.key")"
      echo "NATS_MONITOR_URL=$(shq "$NATS_MONITOR_URL")"
      echo "HAPROXY_STATS_URL=$(shq "$HAPROXY_STATS_URL")"
      echo "NG_DIR=$(shq "$DIR")"
      echo "NG_PORT_BASE=$PORT_BASE"
      echo "NG_BIN=$(shq "$BIN")"
      echo "NG_NODE_FLAGS=$(shq "$NODE_FLAGS")"
      echo "NG_LEASE_MS=$(shq "$LEASE_MS")"
      echo "NG_TOKEN=$(shq "$TOKEN")"
      echo "NG_PG_OWNED=$PG_OWNED"
      echo "NG_PG_BIN=$(shq "$PG_BIN")"
    } >"$tmp"
  )
  mv "$tmp" "$DIR/cluster.env"
}

load_env() {
  [ -f "$DIR/cluster.env" ] || die "no cluster in $DIR (no $DIR/cluster.env): start one with deploy/cluster.sh start --dir $DIR"
  local NG_PORT_BASE="" NG_BIN="" NG_NODE_FLAGS="" NG_LEASE_MS="" NG_TOKEN="" NG_PG_OWNED="" NG_PG_BIN=""
  # shellcheck disable=SC1091
  . "$DIR/cluster.env"
  PORT_BASE=$NG_PORT_BASE
  BIN=$NG_BIN
  NODE_FLAGS=$NG_NODE_FLAGS
  LEASE_MS=$NG_LEASE_MS
  TOKEN=$NG_TOKEN
  PG_OWNED=$NG_PG_OWNED
  PG_BIN=$NG_PG_BIN
  derive
  set_pg_as
}

# ---------------------------------------------------------------- processes

# Runs a command in the background, detached from this script's terminal
# and output, with its output appended to LOG; writes RUN/NAME.pid, and
# RUN/NAME.rc (its exit status) when it ends.
launch() {
  local name=$1 log=$2
  shift 2
  mkdir -p "$RUN"
  rm -f "$RUN/$name.pid" "$RUN/$name.rc"
  (
    trap '' HUP
    "$@" </dev/null >>"$log" 2>&1 &
    child=$!
    echo "$child" >"$RUN/$name.pid.tmp"
    mv "$RUN/$name.pid.tmp" "$RUN/$name.pid"
    rc=0
    wait "$child" || rc=$?
    # Unless a newer process took the name meanwhile (haproxy -sf).
    if [ "$(cat "$RUN/$name.pid" 2>/dev/null)" = "$child" ]; then echo "$rc" >"$RUN/$name.rc"; fi
  ) </dev/null >/dev/null 2>&1 &
  local _
  for _ in $(seq 100); do
    [ -s "$RUN/$name.pid" ] && return 0
    sleep 0.02
  done
  die "$name did not start"
}

# Waits until a test command succeeds; fails with the log's tail if the
# process dies or START_TIMEOUT_S passes.
wait_up() {
  local what=$1 pid=$2 log=$3
  shift 3
  local deadline
  deadline=$(($(now_ms) + START_TIMEOUT_S * 1000))
  while ! "$@"; do
    if [ -n "$pid" ] && ! alive "$pid"; then
      echo "failed"
      echo "cluster.sh: $what exited while starting$(exit_note "$what")" >&2
      tail_log "$log"
      exit 1
    fi
    if [ "$(now_ms)" -ge "$deadline" ]; then
      echo "failed"
      echo "cluster.sh: $what did not come up within $START_TIMEOUT_S s" >&2
      tail_log "$log"
      exit 1
    fi
    sleep 0.1
  done
}

exit_note() {
  local rc
  rc=$(cat "$RUN/$1.rc" 2>/dev/null || true)
  if [ -n "$rc" ]; then echo " (exit status $rc)"; fi
}

# Waits up to S seconds for a pid to end; 1 if it did not.
wait_gone() {
  local pid=$1 s=$2 deadline
  deadline=$(($(now_ms) + s * 1000))
  while alive "$pid"; do
    [ "$(now_ms)" -lt "$deadline" ] || return 1
    sleep 0.05
  done
}

# Sends SIG to a pid (once: a second SIGTERM may mean "hurry" to a node) and
# waits up to S seconds for it to end; 1 if it did not.
signal_wait() {
  local pid=$1 sig=$2 s=$3
  alive "$pid" || return 0
  kill "-$sig" "$pid" 2>/dev/null || true
  wait_gone "$pid" "$s"
}

# ---------------------------------------------------------------- secrets

# 32 random bytes as 64 hex digits.
random_hex() { od -An -N32 -tx1 /dev/urandom | tr -d ' \n'; }

# DIR/secrets (0700): the NATS and Postgres passwords and the cluster key, each made
# once and kept with the cluster's data.
make_secrets() {
  local f
  (
    umask 077
    mkdir -p "$SECRETS"
    for f in nats-password pg-password cluster.key; do
      [ -s "$SECRETS/$f" ] || random_hex >"$SECRETS/$f"
    done
  )
}

# DIR/tls: a test CA (30 days) and a certificate it signs for 127.0.0.1 and localhost
# (server.pem, server.key; haproxy.pem holds both), made once.
make_tls() {
  [ -s "$TLS_DIR/haproxy.pem" ] && return 0
  need openssl openssl
  mkdir -p "$TLS_DIR"
  local ext="$TLS_DIR/server.ext"
  printf '%s\n' 'basicConstraints=critical,CA:FALSE' 'keyUsage=critical,digitalSignature,keyEncipherment' \
    'extendedKeyUsage=serverAuth' 'subjectAltName=IP:127.0.0.1,DNS:localhost' >"$ext"
  if ! {
    (umask 077 && openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 30 \
      -subj "/CN=navguard test CA" -addext 'basicConstraints=critical,CA:TRUE' \
      -addext 'keyUsage=critical,keyCertSign,cRLSign' -keyout "$TLS_DIR/ca.key" -out "$TLS_DIR/ca.pem") &&
      (umask 077 && openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -subj "/CN=127.0.0.1" \
        -keyout "$TLS_DIR/server.key" -out "$TLS_DIR/server.csr") &&
      openssl x509 -req -in "$TLS_DIR/server.csr" -CA "$TLS_DIR/ca.pem" -CAkey "$TLS_DIR/ca.key" \
        -set_serial "0x$(random_hex | cut -c1-16)" -days 30 -extfile "$ext" -out "$TLS_DIR/server.pem"
  } >"$TLS_DIR/openssl.log" 2>&1; then
    tail_log "$TLS_DIR/openssl.log"
    die "openssl could not make the test certificates in $TLS_DIR"
  fi
  (umask 077 && cat "$TLS_DIR/server.pem" "$TLS_DIR/server.key" >"$TLS_DIR/haproxy.pem")
  chmod 644 "$TLS_DIR/ca.pem" "$TLS_DIR/server.pem"
}

# ---------------------------------------------------------------- postgres

find_pg_bin() {
  local initdb
  # The newest Debian version (sort -V: 9.6 before 15), else initdb on the PATH.
  initdb=$(printf '%s\n' /usr/lib/postgresql/*/bin/initdb | sort -V | tail -n 1)
  if [ -x "$initdb" ]; then
    dirname "$initdb"
  elif command -v initdb >/dev/null 2>&1 && command -v pg_ctl >/dev/null 2>&1; then
    dirname "$(command -v initdb)"
  fi
}

set_pg_as() {
  PG_AS=()
  if [ "$(id -u)" -eq 0 ] && [ "${PG_OWNED:-0}" = 1 ]; then PG_AS=(runuser -u nobody --); fi
}

pg_isready_cmd() {
  if [ -n "$PG_BIN" ] && [ -x "$PG_BIN/pg_isready" ]; then
    echo "$PG_BIN/pg_isready"
  elif command -v pg_isready >/dev/null 2>&1; then
    command -v pg_isready
  fi
}

pg_ready() {
  "$(pg_isready_cmd)" -q -d "$PG_URL" -t 2 >/dev/null 2>&1
}

start_postgres() {
  local t0 data="$DIR/pg/data" log="$DIR/pg/postgres.log"
  t0=$(now_ms)
  if [ "$PG_OWNED" = 0 ]; then
    printf 'postgres   %s (external) ... ' "$PG_URL"
    [ -n "$(pg_isready_cmd)" ] || die "pg_isready not found: install the Debian package postgresql-client"
    wait_up postgres "" /dev/null pg_ready
    echo "accepting connections"
    return
  fi
  printf 'postgres   127.0.0.1:%s ... ' "$PG_PORT"
  mkdir -p "$DIR/pg"
  if [ "$(id -u)" -eq 0 ]; then
    chown -R nobody "$DIR/pg"
    runuser -u nobody -- test -w "$DIR/pg" ||
      die "user nobody cannot write $DIR/pg (Postgres refuses to run as root, so it runs as nobody): use a --dir whose parents everybody may enter, e.g. under /tmp"
  fi
  # The server's copy of the certificate and key: Postgres wants its key readable by its
  # own user only.
  (umask 077 && cp "$TLS_DIR/server.pem" "$TLS_DIR/server.key" "$DIR/pg/")
  (umask 077 && cp "$SECRETS/pg-password" "$DIR/pg/pwfile")
  if [ "$(id -u)" -eq 0 ]; then chown nobody "$DIR/pg/server.pem" "$DIR/pg/server.key" "$DIR/pg/pwfile"; fi
  if [ ! -f "$data/PG_VERSION" ]; then
    "${PG_AS[@]}" "$PG_BIN/initdb" -D "$data" -U postgres --auth=scram-sha-256 \
      --pwfile="$DIR/pg/pwfile" --no-sync >"$DIR/pg/initdb.log" 2>&1 || {
      echo "failed"
      tail_log "$DIR/pg/initdb.log"
      exit 1
    }
  fi
  rm -f "$DIR/pg/pwfile"
  # Over TCP on 127.0.0.1 only (no Unix socket, no other address): TLS and a scram-sha-256
  # password, or, with NG_PG_TRUST=1, anything (throw-away clusters only).
  if [ "${NG_PG_TRUST:-0}" = 1 ]; then
    echo "host all all 127.0.0.1/32 trust" >"$data/pg_hba.conf"
  else
    echo "hostssl all all 127.0.0.1/32 scram-sha-256" >"$data/pg_hba.conf"
  fi
  if ! "${PG_AS[@]}" "$PG_BIN/pg_ctl" -D "$data" -l "$log" -w -t "$START_TIMEOUT_S" \
    -o "-p $PG_PORT -c listen_addresses=127.0.0.1 -c unix_socket_directories= -c max_connections=200 -c ssl=on -c ssl_cert_file='$DIR/pg/server.pem' -c ssl_key_file='$DIR/pg/server.key'" \
    start >/dev/null 2>&1; then
    echo "failed"
    echo "cluster.sh: postgres did not come up within $START_TIMEOUT_S s" >&2
    tail_log "$log"
    exit 1
  fi
  wait_up postgres "$(pg_pid)" "$log" pg_ready
  echo "up in $(since_s "$t0") s (pid $(pg_pid))"
}

stop_postgres() {
  [ "$PG_OWNED" = 1 ] || return 0
  [ -f "$DIR/pg/data/postmaster.pid" ] || return 0
  printf 'postgres   stopping ... '
  if "${PG_AS[@]}" "$PG_BIN/pg_ctl" -D "$DIR/pg/data" -m fast -w -t 60 stop >/dev/null 2>&1; then
    echo "stopped"
  else
    echo "pg_ctl stop failed (see $DIR/pg/postgres.log)"
  fi
}

# ---------------------------------------------------------------- nats

nats_ready() { [ "$(http_code "$NATS_MONITOR_URL/healthz")" = 200 ]; }

# The pid of the process listening on TCP port PORT (any address), from /proc (Linux);
# empty when there is none or its sockets cannot be read.
listener_pid() {
  local hex inode fd
  printf -v hex ':%04X' "$1"
  # /proc/net/tcp{,6}: local address in field 2 (hex ADDR:PORT), state in 4 (0A: LISTEN),
  # the socket's inode in 10.
  inode=$(awk -v p="$hex" '$4 == "0A" && substr($2, length($2) - 4) == p { print $10; exit }' \
    /proc/net/tcp /proc/net/tcp6 2>/dev/null || true)
  [ -n "$inode" ] && [ "$inode" != 0 ] || return 0
  fd=$(find /proc/[0-9]*/fd -maxdepth 1 -lname "socket:\[$inode\]" -print -quit 2>/dev/null || true)
  [ -n "$fd" ] || return 0
  fd=${fd#/proc/}
  echo "${fd%%/*}"
}

# The cluster's nats-server: the one listening on its client port, so a NATS restarted by
# hand (whose pid is not the pid file's) is found too; else the pid file's while it lives.
nats_pid() {
  local pid
  pid=$(listener_pid "$NATS_PORT")
  if [ -n "$pid" ] && [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = nats-server ]; then
    echo "$pid"
    return
  fi
  pid=$(pid_of nats)
  if alive "$pid"; then echo "$pid"; fi
}

# DIR/nats.conf (0600): the variables deploy/nats.conf uses, then deploy/nats.conf.
write_nats_conf() {
  (
    umask 077
    {
      echo "# Written by deploy/cluster.sh: the variables, then $NATS_TEMPLATE."
      echo "NG_NATS_PASSWORD: \"$(cat "$SECRETS/nats-password")\""
      echo "NG_TLS_CERT: \"$TLS_DIR/server.pem\""
      echo "NG_TLS_KEY: \"$TLS_DIR/server.key\""
      cat "$NATS_TEMPLATE"
    } >"$DIR/nats.conf"
  )
}

start_nats() {
  local t0
  t0=$(now_ms)
  printf 'nats       127.0.0.1:%s (monitoring %s) ... ' "$NATS_PORT" "$NATS_MON_PORT"
  write_nats_conf
  # Core NATS only: the nodes use no JetStream.
  launch nats "$DIR/nats.log" nats-server -c "$DIR/nats.conf" -a 127.0.0.1 -p "$NATS_PORT" \
    -m "$NATS_MON_PORT" -n navguard-nats
  wait_up nats "$(pid_of nats)" "$DIR/nats.log" nats_ready
  echo "up in $(since_s "$t0") s (pid $(pid_of nats))"
}

# ---------------------------------------------------------------- nodes

# A URL with the password of its user:password@ part replaced by ***.
mask_url() {
  echo "$1" | sed -E 's|^([a-z]+://[^:/@]+):[^@/]*@|\1:***@|'
}

node_ready() { [ "$(http_code "$(node_url "$1")/healthz")" = 200 ]; }

start_node() {
  local k=$1 t0 port url w
  local -a flags=() args=()
  t0=$(now_ms)
  port=$(node_port "$k")
  url=$(node_url "$k")
  printf 'node%-6s %s ... ' "$k" "$url"
  read -r -a flags <<<"$NODE_FLAGS" || true
  for w in "${flags[@]}"; do
    w=${w//@NATS_URL@/$NATS_URL}
    w=${w//@NODE_ID@/node$k}
    w=${w//@NODE_URL@/$url}
    w=${w//@LEASE_MS@/$LEASE_MS}
    args+=("$w")
  done
  # Secrets go in the environment, not on the command line (which `ps` shows); the
  # NATS login, TLS and cluster key only to a node that joins the cluster.
  local -a envs=(env -u NAVGUARD_TOKEN NAVGUARD_DB="$PG_URL")
  if [ -n "$TOKEN" ]; then envs+=(NAVGUARD_TOKEN="$TOKEN"); fi
  if [[ " ${args[*]} " == *" --nats "* ]]; then
    envs+=(NAVGUARD_NATS_USER="$NATS_USER" NAVGUARD_NATS_PASSWORD="$(cat "$SECRETS/nats-password")"
      NAVGUARD_NATS_TLS_CA="$TLS_DIR/ca.pem" NAVGUARD_NATS_TLS=true
      NAVGUARD_CLUSTER_KEY_FILE="$SECRETS/cluster.key")
  fi
  # The command line and the store, a Postgres password masked.
  echo "=== $(date -u +%FT%TZ) cluster.sh: NAVGUARD_DB=$(mask_url "$PG_URL") $BIN --bind 127.0.0.1:$port ${args[*]}" \
    >>"$DIR/node$k.log"
  launch "node$k" "$DIR/node$k.log" "${envs[@]}" "$BIN" --bind "127.0.0.1:$port" "${args[@]}"
  wait_up "node$k" "$(pid_of "node$k")" "$DIR/node$k.log" node_ready "$k"
  echo "up in $(since_s "$t0") s (pid $(pid_of "node$k"))"
}

# ---------------------------------------------------------------- haproxy

# DIR/haproxy.cfg: deploy/haproxy.cfg with one `server nodeK` line per node.
write_haproxy_cfg() {
  local n=$1
  awk -v n="$n" '
    /^[[:space:]]*server node[0-9]+[[:space:]]/ {
      if (!done) {
        indent = $0; sub(/[^[:space:]].*$/, "", indent)
        for (k = 1; k <= n; k++)
          printf "%sserver node%d 127.0.0.1:\"${NG_NODE%d_PORT}\"\n", indent, k, k
        done = 1
      }
      next
    }
    { print }
  ' "$HAPROXY_TEMPLATE" >"$DIR/haproxy.cfg.tmp"
  export_haproxy_env "$n"
  if ! haproxy -c -q -f "$DIR/haproxy.cfg.tmp" >"$DIR/haproxy-check.log" 2>&1; then
    cat "$DIR/haproxy-check.log" >&2
    die "HAProxy refused $DIR/haproxy.cfg.tmp (generated from $HAPROXY_TEMPLATE)"
  fi
  mv "$DIR/haproxy.cfg.tmp" "$DIR/haproxy.cfg"
}

export_haproxy_env() {
  local k
  export NG_LB_PORT="$LB_PORT" NG_STATS_PORT="$STATS_PORT" NG_LB_TLS_PORT="$LB_TLS_PORT"
  export NG_TLS_PEM="$TLS_DIR/haproxy.pem"
  for k in $(seq 1 "$1"); do
    export "NG_NODE${k}_PORT=$(node_port "$k")"
  done
}

# HAProxy's view of a node (UP, DOWN, "UP 1/2", …) from the stats page's CSV.
lb_status() {
  curl -s -m 2 "${HAPROXY_STATS_URL};csv" 2>/dev/null |
    awk -F, -v s="node$1" '$1 == "navguard_nodes" && $2 == s { print $18 }' || true
}

lb_ready() { [ "$(http_code "$LB_URL/healthz")" = 200 ]; }
lb_sees_up() { [ "$(lb_status "$1")" = UP ]; }
lb_sees_all_up() {
  local k
  for k in $(seq 1 "$NODES"); do lb_sees_up "$k" || return 1; done
}

start_haproxy() {
  local t0
  t0=$(now_ms)
  printf 'haproxy    %s (stats %s) ... ' "$LB_URL" "$HAPROXY_STATS_URL"
  write_haproxy_cfg "$NODES"
  launch haproxy "$DIR/haproxy.log" haproxy -db -f "$DIR/haproxy.cfg"
  wait_up haproxy "$(pid_of haproxy)" "$DIR/haproxy.log" lb_ready
  wait_up haproxy "$(pid_of haproxy)" "$DIR/haproxy.log" lb_sees_all_up
  echo "up in $(since_s "$t0") s (pid $(pid_of haproxy)), all $NODES nodes UP"
}

# ---------------------------------------------------------------- commands

resolve_bin() {
  if [ -z "$BIN" ]; then
    if [ -x "$REPO_ROOT/target/release/navguard" ]; then
      BIN="$REPO_ROOT/target/release/navguard"
    elif [ -x "$REPO_ROOT/target/debug/navguard" ]; then
      BIN="$REPO_ROOT/target/debug/navguard"
    else
      command -v cargo >/dev/null 2>&1 ||
        die "no navguard binary under $REPO_ROOT/target and no cargo to build one: install Rust (rustup) or pass --bin"
      echo "no navguard binary under $REPO_ROOT/target: cargo build --release --bin navguard"
      (cd "$REPO_ROOT" && cargo build --release --bin navguard)
      BIN="$REPO_ROOT/target/release/navguard"
    fi
  fi
  [ -f "$BIN" ] || die "navguard binary $BIN not found"
  [ -x "$BIN" ] || die "navguard binary $BIN is not executable"
  BIN="$(cd "$(dirname "$BIN")" && pwd)/$(basename "$BIN")"
}

start_failed() {
  echo "cluster.sh: start failed; stopping what was started (logs stay in $DIR)" >&2
  stop_all >&2 || true
}

cmd_start() {
  [[ "$NODES" =~ ^[1-9]$ ]] || die "--nodes must be 1 to 9 (node ports P+1..P+N stop below NATS at P+10), not '$NODES'"
  if ! [[ "$PORT_BASE" =~ ^[0-9]+$ ]] || [ "$PORT_BASE" -lt 1024 ] || [ "$PORT_BASE" -gt 65500 ]; then
    die "--port-base must be a number from 1024 to 65500, not '$PORT_BASE'"
  fi
  [[ "$LEASE_MS" =~ ^[0-9]+$ ]] || die "--lease-ms must be a number of milliseconds, not '$LEASE_MS'"
  derive
  need curl curl
  need openssl openssl
  need nats-server nats-server
  need haproxy haproxy
  if [ -n "$PG_URL_OPT" ]; then
    PG_OWNED=0
    PG_URL=$PG_URL_OPT
    PG_BIN=$(find_pg_bin)
  else
    PG_OWNED=1
    if [ "${NG_PG_TRUST:-0}" = 1 ]; then
      PG_URL="postgres://postgres@127.0.0.1:$PG_PORT/postgres"
    else
      PG_URL="postgres://postgres:@PG_PASSWORD@@127.0.0.1:$PG_PORT/postgres?sslmode=verify-full&sslrootcert=$TLS_DIR/ca.pem"
    fi
    PG_BIN=$(find_pg_bin)
    [ -n "$PG_BIN" ] || die "Postgres server binaries (initdb, pg_ctl) not found: install the Debian package postgresql (apt-get install postgresql), or pass --pg-url"
    if [ "$(id -u)" -eq 0 ]; then need runuser util-linux; fi
  fi
  set_pg_as
  if [ -f "$DIR/cluster.env" ]; then
    local f running=""
    for f in "$DIR"/run/*.pid; do
      if [ -f "$f" ] && alive "$(cat "$f")"; then running="$running $(basename "$f" .pid)"; fi
    done
    if [ -n "$running" ]; then
      die "a cluster is already running in $DIR ($running ): see deploy/cluster.sh status --dir $DIR, or stop it first"
    fi
  fi
  local k
  port_must_be_free "$LB_PORT" "HAProxy frontend"
  port_must_be_free "$LB_TLS_PORT" "HAProxy TLS frontend"
  for k in $(seq 1 "$NODES"); do port_must_be_free "$(node_port "$k")" "node$k"; done
  port_must_be_free "$NATS_PORT" "NATS"
  port_must_be_free "$NATS_MON_PORT" "NATS monitoring"
  port_must_be_free "$STATS_PORT" "HAProxy stats"
  if [ "$PG_OWNED" = 1 ]; then port_must_be_free "$PG_PORT" "Postgres"; fi
  resolve_bin
  NODE_FLAGS=${NG_NODE_FLAGS-$DEFAULT_NODE_FLAGS}

  mkdir -p "$DIR" "$DIR/run"
  rm -f "$DIR"/run/*.pid "$DIR"/run/*.rc
  make_secrets
  make_tls
  PG_URL=${PG_URL//@PG_PASSWORD@/$(cat "$SECRETS/pg-password")}
  write_env
  trap start_failed EXIT
  echo "starting a navguard cluster of $NODES nodes in $DIR ($BIN)"
  start_postgres
  start_nats
  for k in $(seq 1 "$NODES"); do start_node "$k"; done
  start_haproxy
  write_env
  trap - EXIT

  echo
  echo "cluster up:"
  echo "  load balancer   $LB_URL   (dashboard: $LB_URL/)"
  echo "  load balancer   $LB_TLS_URL   (TLS; CA $TLS_DIR/ca.pem)"
  for k in $(seq 1 "$NODES"); do
    printf '  node%-11s %s   pid %s   log %s\n' "$k" "$(node_url "$k")" "$(pid_of "node$k")" "$DIR/node$k.log"
  done
  if [ "$PG_OWNED" = 1 ]; then
    echo "  postgres        $(mask_url "$PG_URL")   log $DIR/pg/postgres.log"
  else
    echo "  postgres        $(mask_url "$PG_URL")   (external)"
  fi
  echo "  nats            $NATS_URL   monitoring $NATS_MONITOR_URL/varz   log $DIR/nats.log"
  echo "  haproxy stats   $HAPROXY_STATS_URL   log $DIR/haproxy.log"
  echo "  environment     $DIR/cluster.env   (. $DIR/cluster.env)"
  echo "stop with: $0 stop --dir $DIR"
}

stop_all() {
  local k pid
  local -a nodes=()
  for k in $(seq 1 "$NODES"); do
    pid=$(pid_of "node$k")
    if alive "$pid"; then
      kill -TERM "$pid" 2>/dev/null || true
      nodes+=("$k")
    fi
  done
  if [ "${#nodes[@]}" -gt 0 ]; then
    local t0
    t0=$(now_ms)
    printf 'nodes      draining %s ... ' "$(printf 'node%s ' "${nodes[@]}")"
    for k in "${nodes[@]}"; do
      pid=$(pid_of "node$k")
      if ! wait_gone "$pid" "$DRAIN_TIMEOUT_S"; then
        printf '(node%s still running after %s s: SIGKILL) ' "$k" "$DRAIN_TIMEOUT_S"
        signal_wait "$pid" KILL 5 || true
      fi
    done
    echo "stopped in $(since_s "$t0") s"
  fi
  pid=$(pid_of haproxy)
  if alive "$pid"; then
    printf 'haproxy    stopping ... '
    signal_wait "$pid" TERM 10 || signal_wait "$pid" KILL 5 || true
    echo "stopped"
  fi
  pid=$(nats_pid)
  if alive "$pid"; then
    printf 'nats       stopping ... '
    signal_wait "$pid" TERM 10 || signal_wait "$pid" KILL 5 || true
    echo "stopped"
  fi
  stop_postgres
  rm -f "$RUN"/*.pid "$RUN"/*.rc
}

cmd_stop() {
  load_env
  stop_all
  write_env
  if [ "$PURGE" = 1 ]; then
    rm -rf "$DIR"
    echo "removed $DIR"
  fi
}

cmd_status() {
  load_env
  local all_up=0 pid code k state
  line() { printf '%-9s %-5s %-11s %s\n' "$1" "$2" "$3" "$4"; }
  # Postgres
  if [ "$PG_OWNED" = 1 ]; then
    pid=$(pg_pid)
    if alive "$pid" && pg_ready; then line postgres up "pid $pid" "$(mask_url "$PG_URL")"; else
      line postgres down - "$(mask_url "$PG_URL")"
      all_up=3
    fi
  else
    if [ -n "$(pg_isready_cmd)" ] && pg_ready; then line postgres up external "$(mask_url "$PG_URL")"; else
      line postgres down external "$(mask_url "$PG_URL")"
      all_up=3
    fi
  fi
  pid=$(nats_pid)
  if alive "$pid" && nats_ready; then line nats up "pid $pid" "$NATS_URL (monitoring $NATS_MONITOR_URL)"; else
    line nats down - "$NATS_URL (monitoring $NATS_MONITOR_URL)"
    all_up=3
  fi
  for k in $(seq 1 "$NODES"); do
    pid=$(pid_of "node$k")
    state=$(lb_status "$k")
    if alive "$pid"; then
      code=$(http_code "$(node_url "$k")/healthz")
      line "node$k" up "pid $pid" "$(node_url "$k") healthz $code, haproxy ${state:-?}"
      [ "$code" = 200 ] || all_up=3
    else
      line "node$k" down - "$(node_url "$k") haproxy ${state:-?}$(exit_note "node$k")"
      all_up=3
    fi
  done
  pid=$(pid_of haproxy)
  if alive "$pid"; then
    line haproxy up "pid $pid" "$LB_URL healthz $(http_code "$LB_URL/healthz"), stats $HAPROXY_STATS_URL"
  else
    line haproxy down - "$LB_URL, stats $HAPROXY_STATS_URL"
    all_up=3
  fi
  return "$all_up"
}

node_arg() {
  [ -n "$NODE_K" ] || die "$CMD needs a node number: deploy/cluster.sh $CMD K"
  if ! [[ "$NODE_K" =~ ^[1-9]$ ]] || [ "$NODE_K" -gt "$NODES" ]; then
    die "no node $NODE_K (the cluster in $DIR has nodes 1 to $NODES)"
  fi
}

cmd_kill() {
  load_env
  node_arg
  local pid
  pid=$(pid_of "node$NODE_K")
  alive "$pid" || die "node$NODE_K is not running"
  signal_wait "$pid" KILL 10 || die "node$NODE_K (pid $pid) still there 10 s after SIGKILL"
  echo "node$NODE_K (pid $pid) killed with SIGKILL"
  write_env
}

cmd_drain() {
  load_env
  node_arg
  local pid t0 rc _
  pid=$(pid_of "node$NODE_K")
  alive "$pid" || die "node$NODE_K is not running"
  t0=$(now_ms)
  if ! signal_wait "$pid" TERM "$DRAIN_TIMEOUT_S"; then
    die "node$NODE_K (pid $pid) still running $DRAIN_TIMEOUT_S s after SIGTERM (not killed; deploy/cluster.sh kill $NODE_K to force)"
  fi
  # The launcher writes the exit status just after the process ends.
  for _ in $(seq 50); do
    [ -s "$RUN/node$NODE_K.rc" ] && break
    sleep 0.02
  done
  rc=$(cat "$RUN/node$NODE_K.rc" 2>/dev/null || echo '?')
  echo "node$NODE_K (pid $pid) drained in $(since_s "$t0") s, exit status $rc"
  write_env
  [ "$rc" = 0 ]
}

cmd_restart() {
  load_env
  node_arg
  local t0
  alive "$(pid_of "node$NODE_K")" && die "node$NODE_K is running (pid $(pid_of "node$NODE_K")): drain or kill it first"
  port_must_be_free "$(node_port "$NODE_K")" "node$NODE_K"
  t0=$(now_ms)
  start_node "$NODE_K"
  write_env
  if alive "$(pid_of haproxy)"; then
    printf 'haproxy    waiting until node%s is UP ... ' "$NODE_K"
    wait_up haproxy "$(pid_of haproxy)" "$DIR/haproxy.log" lb_sees_up "$NODE_K"
    echo "UP $(since_s "$t0") s after the restart began"
  fi
}

cmd_add() {
  load_env
  local k=$((NODES + 1)) old t0
  [ "$k" -le 9 ] || die "the cluster already has 9 nodes (node ports P+1..P+9 stop below NATS at P+10)"
  port_must_be_free "$(node_port "$k")" "node$k"
  old=$(pid_of haproxy)
  alive "$old" || die "haproxy is not running: deploy/cluster.sh stop --dir $DIR, then start"
  start_node "$k"
  NODES=$k
  write_env
  t0=$(now_ms)
  printf 'haproxy    reloading with %s servers ... ' "$NODES"
  write_haproxy_cfg "$NODES"
  launch haproxy "$DIR/haproxy.log" haproxy -db -f "$DIR/haproxy.cfg" -sf "$old"
  wait_up haproxy "$(pid_of haproxy)" "$DIR/haproxy.log" lb_sees_up "$k"
  echo "reloaded in $(since_s "$t0") s (pid $(pid_of haproxy), was $old), node$k UP"
}

# ---------------------------------------------------------------- arguments

CMD=${1:-}
[ -n "$CMD" ] || {
  usage >&2
  exit 2
}
shift
case "$CMD" in
  -h | --help | help)
    usage
    exit 0
    ;;
  start | stop | status | kill | drain | restart | add) ;;
  *) die "unknown command '$CMD' (deploy/cluster.sh --help)" ;;
esac

DIR="${TMPDIR:-/tmp}/navguard-cluster"
PORT_BASE=18080
NODES=3
BIN=""
PG_URL_OPT=${NAVGUARD_PG_URL:-}
LEASE_MS=3000
TOKEN=${NAVGUARD_TOKEN:-}
PURGE=0
NODE_K=""
PG_OWNED=0
PG_BIN=""
PG_URL=""
NODE_FLAGS=""
PG_AS=()

value() {
  if [ "$#" -lt 2 ] || [ -z "$2" ]; then die "$1 needs a value"; fi
  printf '%s\n' "$2"
}

while [ "$#" -gt 0 ]; do
  case "$1" in
    --dir) DIR=$(value "$@"); shift ;;
    --dir=*) DIR=${1#*=} ;;
    --port-base) PORT_BASE=$(value "$@"); shift ;;
    --port-base=*) PORT_BASE=${1#*=} ;;
    --nodes) NODES=$(value "$@"); shift ;;
    --nodes=*) NODES=${1#*=} ;;
    --bin) BIN=$(value "$@"); shift ;;
    --bin=*) BIN=${1#*=} ;;
    --pg-url) PG_URL_OPT=$(value "$@"); shift ;;
    --pg-url=*) PG_URL_OPT=${1#*=} ;;
    --lease-ms) LEASE_MS=$(value "$@"); shift ;;
    --lease-ms=*) LEASE_MS=${1#*=} ;;
    --token) TOKEN=$(value "$@"); shift ;;
    --token=*) TOKEN=${1#*=} ;;
    --purge) PURGE=1 ;;
    -h | --help)
      usage
      exit 0
      ;;
    -*) die "unknown option '$1' for $CMD (deploy/cluster.sh --help)" ;;
    *)
      [ -z "$NODE_K" ] || die "unexpected argument '$1'"
      NODE_K=$1
      ;;
  esac
  shift
done

case "$CMD" in
  start | stop | status | add) [ -z "$NODE_K" ] || die "$CMD takes no node number" ;;
esac
[ "$PURGE" = 0 ] || [ "$CMD" = stop ] || die "--purge is an option of stop"
case "$DIR" in
  /*) ;;
  *) DIR="$PWD/$DIR" ;;
esac

case "$CMD" in
  start) cmd_start ;;
  stop) cmd_stop ;;
  status) cmd_status ;;
  kill) cmd_kill ;;
  drain) cmd_drain ;;
  restart) cmd_restart ;;
  add) cmd_add ;;
esac
