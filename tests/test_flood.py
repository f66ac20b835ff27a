"""A flood is said, never silent (issue 31, 7th fault): what the gate refuses is counted per
sender (as its key names it) and a system problem is raised when a sender's refusals pass
100, 1,000, ... — once per threshold, not once per message."""
from __future__ import annotations

import uuid

from saim_mesh import scenario as S
from saim_mesh.protocol import gate as G
from saim_mesh.live.peer import LivePeer
from saim_mesh.launch.zenoh_config import config

from .conftest import SMALL


def test_sender_of_names_who_put_it():
    assert G.sender_of("saim/x/src/cp.A") == "src/cp.A"
    assert G.sender_of("saim/x/cmd/A2/ack/C") == "cmd/C"
    assert G.sender_of("saim/x/dir/BN/order") == "dir/BN"
    assert G.sender_of("") == "(unknown)"
    assert G.sender_of("saim/x/weird") == "(other keys)"


def test_a_flood_of_junk_from_one_source_is_counted_and_said_at_each_threshold():
    sc = S.load(SMALL, events=False)
    root = f"test/{uuid.uuid4().hex[:8]}"
    peer = LivePeer(sc, "A2", config(["tcp/127.0.0.1:0"], None), root, ["cp.A", "cp.rest"], log=lambda *a, **k: None)
    key = peer.ks.src("cp.A")
    for i in range(1_000):
        peer.receive(b"\x93junk" + i.to_bytes(4, "big"), key)
    peer.receive(b"\xc1", peer.ks.src("cp.rest"))
    s = peer.summary()
    assert s["rejects_by_sender"] == {"src/cp.A": 1_000, "src/cp.rest": 1}
    floods = [a for a in peer.ea.alerts if a.details.get("event") == "flood"]
    assert [a.details["refused"] for a in floods] == [100, 1_000]
    assert all(a.category == "system-problem" and a.subjects == ("cp.A",) for a in floods)
    assert "src/cp.A" in floods[0].message
