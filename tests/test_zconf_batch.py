"""The mesh's Zenoh configuration uses 16 KB batches (configs/zenoh-peer.json5): a
sample queued in a busy EA's channel then pins 16 KB, not 64 KB. A message larger than a
batch (a store reply, a big batch of reports) must still arrive whole and in order,
through a router as in the brigade topology."""
from __future__ import annotations

import pytest

from saim_mesh.launch.zenoh_config import config, free_port

from .conftest import wait_until

pytestmark = pytest.mark.timeout(60)


def test_the_mesh_config_asks_for_small_batches():
    conf = config(mode="client", connect=["tcp/127.0.0.1:1"])
    assert conf.get_json("transport/link/tx/batch_size") == "16384"
    assert conf.get_json("transport/link/rx/buffer_size") == "16384"


@pytest.mark.parametrize("size", [100, 16_000, 16_384 * 3 + 7, 300_000])
def test_messages_of_any_size_cross_a_router_whole_and_in_order(size):
    import zenoh
    ep = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(config(mode="router", listen=[ep])), \
            zenoh.open(config(mode="client", connect=[ep])) as a, \
            zenoh.open(config(mode="client", connect=[ep])) as b:
        sub = b.declare_subscriber("test/big", zenoh.handlers.FifoChannel(100))
        pub = a.declare_publisher("test/big", congestion_control=zenoh.CongestionControl.BLOCK)
        wait_until(lambda: pub.matching_status.matching, 20, "the publisher sees the subscriber through the router")
        sent = [bytes([i]) * size for i in range(5)]
        for p in sent:
            pub.put(p)
        got: list[bytes] = []
        def take() -> bool:
            while (s := sub.handler.try_recv()) is not None:
                got.append(s.payload.to_bytes())
            return len(got) >= len(sent)
        wait_until(take, 30, f"5 messages of {size} bytes")
        assert got == sent


def test_a_router_link_outlasts_a_full_batch_on_a_64_kbit_radio():
    """Zenoh reads a batch whole within the lease: a 16 KB batch takes 2 s at 64 kbit/s,
    so at the leaves' 2 s lease a router link that sent full batches (a catch-up after a
    heal) expired, again and again. Routers take a longer lease; leaves keep theirs (a
    dead process on the same host is noticed at once)."""
    batch_bits = 8 * int(config(mode="router", listen=["tcp/127.0.0.1:1"]).get_json("transport/link/tx/batch_size"))
    router = int(config(mode="router", listen=["tcp/127.0.0.1:1"]).get_json("transport/link/tx/lease"))
    leaf = int(config(mode="client", connect=["tcp/127.0.0.1:1"]).get_json("transport/link/tx/lease"))
    assert router >= 4 * 1000 * batch_bits / 64_000   # ms: four full batches at 64 kbit/s
    assert leaf == 2000
