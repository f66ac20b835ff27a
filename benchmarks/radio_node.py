"""One process of `radio_priority`: a router, a live publisher, a bulk publisher or the
subscriber that times the live messages. Run inside a namespaced host."""
from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time

import zenoh

from saim_mesh.launch import zenoh_config


def main(argv: list[str]) -> int:
    role, ep, *rest = argv
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    if role == "router":
        conf = zenoh_config.config(listen=[ep], connect=rest, mode="router")
        if os.environ.get("RADIO_SNDBUF"):
            conf.insert_json5("transport/link/tcp/so_sndbuf", os.environ["RADIO_SNDBUF"])
        if os.environ.get("RADIO_BATCH"):
            conf.insert_json5("transport/link/tx/batch_size", os.environ["RADIO_BATCH"])
        with zenoh.open(conf):
            print("ready", flush=True)
            stop.wait()
        return 0
    with zenoh.open(zenoh_config.config(connect=[ep], mode="client")) as s:
        key = rest[0]
        if role == "bulk":   # a catch-up as a yielding journal sends it: DROP, low priority, 8 kB every 20 ms or RADIO_BULK_EVERY s
            pub = s.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP,
                                      priority=zenoh.Priority.DATA_LOW)
            every = float(os.environ.get("RADIO_BULK_EVERY", "0.02"))
            print("ready", flush=True)
            while True:
                pub.put(os.urandom(8000))
                if stop.wait(every):
                    break
        elif role == "live":   # a source's live frames: BLOCK, 200 bytes every 100 ms
            pub = s.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
            print("ready", flush=True)
            i = 0
            while not stop.wait(0.1):
                pub.put(json.dumps({"i": i, "t": time.time()}).encode().ljust(200))
                i += 1
        else:
            def took(smp) -> None:
                b = smp.payload.to_bytes()
                if b[:1] == b"{":
                    print("lat", round(time.time() - json.loads(b)["t"], 4), flush=True)
                else:
                    print("bulk", len(b), flush=True)
            s.declare_subscriber(key, took)
            print("ready", flush=True)
            stop.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
