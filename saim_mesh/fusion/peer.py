"""A fusion node as a Zenoh peer: takes its sensor group's hits (in the replay's order,
by sequence number and clock ticks) and publishes fused tracks into the mesh."""
from __future__ import annotations

import heapq
import json
import random

import msgpack
import zenoh

import time

from dissemination.keyspace import KeySpace, matcher, place
from saim_mesh import messages as M
from saim_mesh.scenario import Scenario

from .node import FusionNode

BLOCK = zenoh.CongestionControl.BLOCK


def _eas_present(s, ks: KeySpace) -> bool:
    for r in s.liveliness().get(ks.alive("*", "*"), timeout=2.0):
        if r.ok is not None and not str(r.ok.key_expr).split("/")[-2].startswith("fusion-"):
            return True
    return False


def run_fusion_peer(sc: Scenario, group: str, conf, root: str, shuffle: int | None = None,
                    linger_s: float = 30.0) -> dict:
    ks = KeySpace(root)
    node = FusionNode(group, sc.projection)
    rnd = random.Random(shuffle) if shuffle is not None else None
    dec = M.Decoder()
    sent = 0
    log: list[tuple[str, bytes]] = []     # what we published, for peers that subscribe later

    def serve(query) -> None:
        """Answered at once on Zenoh's thread: an EA waiting for its catch-up must not wait
        for our next clock tick (a paced replay may be waiting for that EA)."""
        keys = msgpack.unpackb(query.payload.to_bytes()).get("keys") if query.payload is not None else None
        match = matcher(keys) if keys is not None else (lambda k: True)
        query.reply(ks.fusion_store(group), msgpack.packb({"entries": [p for k, p in list(log) if match(k)]}))

    with zenoh.open(conf) as s:
        store = s.declare_queryable(ks.fusion_store(group), serve)
        clock = s.declare_subscriber(ks.clock(), zenoh.handlers.FifoChannel(1_000_000))
        hits = s.declare_subscriber(f"{root}/hit/{group}/*", zenoh.handlers.FifoChannel(1_000_000))
        token = s.liveliness().declare_token(ks.alive(f"fusion-{group}", str(s.info.zid())))
        print(f"ready fusion-{group}", flush=True)
        heap: list = []
        while True:
            info = msgpack.unpackb(clock.recv().payload.to_bytes())
            while (smp := hits.try_recv()) is not None:
                seq = int.from_bytes(smp.attachment.to_bytes(), "big") if smp.attachment is not None else 0
                m = dec(smp.payload.to_bytes())
                if m is not None:
                    heapq.heappush(heap, (seq, m))
            out = []
            while heap and heap[0][0] <= info["seq"]:
                out += node.add(heapq.heappop(heap)[1])
            out += node.flush(info["t"])
            if rnd is not None:
                rnd.shuffle(out)   # tests: arrival order must not matter
            for tr in out:
                x, y = sc.projection.to_xy(tr.lon, tr.lat)
                key, payload = f"{root}/trk/{place(x, y)}/{tr.track}", M.encode(tr)
                log.append((key, payload))
                s.put(key, payload, congestion_control=BLOCK)
                sent += 1
            # after its tracks on the same session: an EA that sees this has them all
            s.put(ks.fusion_tick(group), msgpack.packb({"t": info["t"]}), congestion_control=BLOCK)
            if info["end"]:
                break
        linger = time.monotonic() + linger_s   # keep answering catch-up queries while EAs finish
        while time.monotonic() < linger and _eas_present(s, ks):
            time.sleep(0.2)    # queries are answered by the callback meanwhile
        token.undeclare()
        store.undeclare()
    return {"group": group, "hits_in": node.stats["hits_in"], "tracks_out": sent}


def main_fusion(sc: Scenario, group: str, conf, root: str, shuffle: int | None) -> int:
    print("summary " + json.dumps(run_fusion_peer(sc, group, conf, root, shuffle)), flush=True)
    return 0
