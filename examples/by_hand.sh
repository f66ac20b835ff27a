#!/usr/bin/env bash
# A live mesh launched by hand: one Zenoh router, an EA peer per unit named, and the
# scenario's command-post sources (`saim-mesh sources`), every process a client of the
# router (since Zenoh 1.9 peers do not relay for each other). What `mesh up` does for you.
#
#   examples/by_hand.sh [--secure] SCENARIO OUT_DIR PORT UNIT...
#   examples/by_hand.sh scenarios/small out/by-hand 7447 BN A A2
#
# --secure: a test CA and certificates (`saim-mesh certs --routers hub`), mutual TLS and
# the mesh's access control. Each EA's alerts go to OUT_DIR/UNIT.jsonl, its log and last
# line (`summary {...}`) to OUT_DIR/UNIT.log. Exits once every EA has finished.
set -euo pipefail
secure=0
if [[ ${1:-} == --secure ]]; then secure=1; shift; fi
if (($# < 4)); then
  echo "usage: $0 [--secure] SCENARIO OUT_DIR PORT UNIT..." >&2
  exit 2
fi
sc=$1 out=$2 port=$3
shift 3
units=("$@")
sm=${SAIM_MESH:-saim-mesh}
mkdir -p "$out"
root="saim/by-hand/$$"

if ((secure)); then
  "$sm" certs "$sc" --out "$out/pki" --routers hub >/dev/null
  ep="tls/127.0.0.1:$port"
  z=(--root "$root" --pki "$out/pki" --routers hub)
else
  ep="tcp/127.0.0.1:$port"
  z=(--root "$root")
fi

pids=()
trap 'kill "${pids[@]}" 2>/dev/null || true; wait 2>/dev/null || true' EXIT

ready() {   # ready LOG TEXT: wait until the process writing LOG has said TEXT (at most 120 s)
  local n=0
  until grep -q "$2" "$1" 2>/dev/null; do
    ((n++ < 1200)) || { echo "$1: no '$2' within 120 s" >&2; exit 1; }
    sleep 0.1
  done
}

"$sm" router --scenario "$sc" --name hub --listen "$ep" "${z[@]}" >"$out/router.log" 2>&1 &
pids+=($!)
ready "$out/router.log" "router ready hub"

mapfile -t sources < <("$sm" sources "$sc" | cut -d' ' -f1)
peers=()
for u in "${units[@]}"; do   # each EA takes from the sources only what it depends on
  "$sm" peer --scenario "$sc" --unit "$u" --sources "${sources[@]}" --connect "$ep" --mode client "${z[@]}" \
    --out "$out/$u.jsonl" >"$out/$u.log" 2>&1 &
  pids+=($!) peers+=($!)
done
for u in "${units[@]}"; do ready "$out/$u.log" "ready $u"; done

while read -r name cmd; do   # NAME saim-mesh source SCENARIO --name NAME ARGS...   # comment
  read -ra argv <<<"${cmd%%#*}"
  "$sm" "${argv[@]:1}" --connect "$ep" --mode client "${z[@]}" --speed max --state "$out/state" \
    >"$out/$name.log" 2>&1 &
  pids+=($!)
done < <("$sm" sources "$sc")

for p in "${peers[@]}"; do wait "$p"; done
for u in "${units[@]}"; do echo "$u: $(wc -l <"$out/$u.jsonl") alerts in $out/$u.jsonl"; done
