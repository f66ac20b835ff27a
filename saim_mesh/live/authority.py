"""A live EA's intake of directives (orders down, confirmations up: `saim_mesh/authority/directives.py`).

Checked like every input (bounded, decoded into a typed struct, the signature opened in
secure mode), deduplicated (a late joiner hears the same directive from several EAs'
journals), kept in `(at, by, n)` order until the EA's event time reaches `at`, and kept
afterwards as received so this EA can hand them to a late joiner (`dirj/<unit>`)."""
from __future__ import annotations

import hashlib
import heapq

from ..authority import directives as D
from ..protocol import messages as M
from ..protocol import gate as G
from ..protocol import wire as W

MAX_DIRECTIVES = 10_000   # taken per EA over a run (a flood beyond is refused and counted)
MAX_BYTES = 64 * 1024     # one directive's payload, envelope included (a plan version's missions: 48 kB)


class DirectiveIntake:
    def __init__(self, root: str, gate: G.Gate):
        self.root, self.gate = root, gate
        self.pending: list[tuple[tuple, D.Taken]] = []
        self.seen: set[bytes] = set()
        self.reqs: set[tuple[str, str]] = set()   # (by, req) taken: the same directive again is a repeat
        self.kept: list[tuple[str, bytes]] = []   # (key, payload as received): served to late joiners

    def check(self, key: str, payload: bytes) -> tuple[D.Taken, bytes] | None:
        """The directive in a payload off the wire and its opened body, or None (a repeat:
        silently; anything bad: counted in the gate's rejects, one line said)."""
        parsed = D.parse_key(self.root, key)
        try:
            if parsed is None:
                raise M.MessageError("directive", "(key)", f"not a directive key: {key[:80]!r}")
            if len(payload) > MAX_BYTES:
                raise M.MessageError("directive", "(bytes)", f"{len(payload)} bytes, over the {MAX_BYTES} limit")
            # a repeat is the same bytes on the same key: the same bytes on another key are
            # checked as new (a signed envelope names its key: moved, it is refused and counted)
            digest = hashlib.blake2b(key.encode() + b"\0" + payload, digest_size=16).digest()
            if digest in self.seen:
                return None
            if len(self.seen) >= MAX_DIRECTIVES:
                raise M.MessageError("directive", "(count)", f"over {MAX_DIRECTIVES} directives in one run")
            body = payload
            ver = self.gate.verifier
            if payload[:1] in W.ENVELOPE_HEADS:
                if ver is None:
                    raise M.MessageError("signed", "(envelope)", "a signed directive, and no signers' keys here")
                signed_key, body = ver.open(payload, key)
                if signed_key != key:
                    raise M.MessageError("directive", "key", f"signed for {signed_key[:80]!r}, came on {key[:80]!r}")
            elif ver is not None and ver.require:
                raise M.MessageError("directive", "(signature)", "an unsigned directive: must be signed in secure mode")
            by, kind = parsed
            d = D.decode(kind, body, MAX_BYTES)
            self.gate._bound("directive", d.at)
        except M.MessageError as e:
            self.gate.rejects.add(e, key)
            return None
        self.seen.add(digest)
        if (by, d.req) in self.reqs:
            return None   # taken already (before a restart, from the journal)
        self.reqs.add((by, d.req))
        self.kept.append((key, payload))
        return D.Taken(by, d), body

    def hold(self, tk: D.Taken) -> None:
        heapq.heappush(self.pending, (tk.sort_key(), tk))

    def due(self, bound: float) -> D.Taken | None:
        """The next held directive whose `at` every source has promised (the facts before
        it are all in), taken off the heap; else None."""
        if self.pending and self.pending[0][1].t <= bound:
            return heapq.heappop(self.pending)[1]
        return None

    def reset(self) -> None:
        """A rebuilt EA: what was held is fed again from the input journal."""
        self.pending = []
