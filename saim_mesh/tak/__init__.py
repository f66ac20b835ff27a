"""Cursor-on-Target gateway (issue #10, docs/tak.md): the mesh's picture and alerts out to
TAK clients and servers (UDP multicast SA, TCP, TLS; XML or TAK protocol v1), and TAK
clients' position reports (PLI) in, as location reports of the entities they are mapped to.

Modules: `types` (CoT / MIL-STD-2525B type codes), `cot` (build and parse one event,
pure functions), `pli` (PLI in -> LocationReport), `picture` (the latest state -> events),
`transports` (pytak senders and listeners), `gateway` (the mesh peer, `main_tak`)."""
