"""What signatures cost per message: Ed25519 signing (a console's commands and directives,
an EA's notices) and checking through `gate.Gate` (every receiver), against the same gate
on unsigned messages; measured on an order, whoever signs it (the cost is the envelope's).

CPU time of this process per message (`time.process_time`), the best of several rounds:
on a shared 2-core machine wall time mostly measures the neighbours. Writes
bench/results/sign.json."""
from __future__ import annotations

import argparse
import platform
import time

import cryptography
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from dissemination.keyspace import KeySpace

from saim_mesh.protocol import messages as M
from saim_mesh.protocol.gate import Gate
from saim_mesh.security import sign as G
from . import results

from . import ROOT


def per_message_us(fn, n: int, rounds: int) -> float:
    """Best CPU microseconds per call of fn(i), i in range(n), over `rounds` rounds."""
    best = float("inf")
    for _ in range(rounds):
        t = time.process_time()
        for i in range(n):
            fn(i)
        best = min(best, (time.process_time() - t) / n)
    return round(best * 1e6, 2)


def measure(n: int = 2000, rounds: int = 5) -> dict:
    ks = KeySpace("bench")
    key = Ed25519PrivateKey.generate()
    signer = G.Signer("hq", key)   # an identity allowed to sign orders here (the rules below)
    order = M.Order(10.0, "execute-plan", "p1", "A2")
    okey, body = ks.key(order, None, None), M.encode(order)
    pos = M.encode(M.LocationReport(1.0, "A2S1", 10.0, 50.0))

    def gate() -> Gate:   # a fresh window each round: every counter is new to it
        return Gate(1e6, verifier=G.Verifier({"hq": key.public_key()}, {"hq": ["ord/**"]}, "bench",
                                               window=n * rounds + 1))
    envs = [signer.sign(okey, body, i + 1) for i in range(n)]
    sig, canon, pub = key.sign(body), body, key.public_key()
    gates = []

    def signed(i: int) -> None:
        if i == 0:
            gates.append(gate())
        assert gates[-1].data(envs[i], okey) is not None
    plain, secure = Gate(1e6), gate()
    out = {
        "ed25519_sign_raw_us": per_message_us(lambda i: key.sign(canon), n, rounds),
        "ed25519_verify_raw_us": per_message_us(lambda i: pub.verify(sig, canon), n, rounds),
        "sign_envelope_us": per_message_us(lambda i: signer.sign(okey, body, i + 1), n, rounds),
        "gate_signed_order_us": per_message_us(signed, n, rounds),
        "gate_unsigned_order_us": per_message_us(lambda i: plain.data(body, okey), n, rounds),
        "gate_position_open_mode_us": per_message_us(lambda i: plain.data(pos, "x"), n, rounds),
        "gate_position_secure_mode_us": per_message_us(lambda i: secure.data(pos, "x"), n, rounds),
        "envelope_overhead_bytes": len(envs[0]) - len(body),
        "order_bytes": len(body),
    }
    out["verify_cost_us"] = round(out["gate_signed_order_us"] - out["gate_unsigned_order_us"], 2)
    out["sign_cost_us"] = out["sign_envelope_us"]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="bench_sign", description=__doc__.split("\n\n")[0])
    ap.add_argument("-n", type=int, default=2000, help="messages per round")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "sign.json"))
    a = ap.parse_args(argv)
    res = {"what": "CPU microseconds per message, best of rounds", "n": a.n, "rounds": a.rounds,
           "python": platform.python_version(), "cryptography": cryptography.__version__,
           **measure(a.n, a.rounds)}
    results.write(a.out, res, echo=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
