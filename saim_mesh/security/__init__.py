"""Identities (mTLS certificates, one per role) and Zenoh access-control rules
generated from the scenario: `pki` makes the certificates, `acl` the configuration.

Roles and certificate common names: `ea.<unit>`, `source.<name>`, `observer`
(read-only: alerts and presence), `console` (observer + commands), `console.<unit>`,
`tak`, `router.<name>`. `sign`
signs what carries authority with each identity's own Ed25519 key (it survives relays)."""
from __future__ import annotations

import importlib

_WHERE = {"SecurityError": "pki", "check_files": "pki", "check_identity": "pki", "make_pki": "pki",
          "names_for": "pki", "access_control": "acl", "endpoint_tls": "acl", "secure_config": "acl",
          "tls_config": "acl", "Signer": "sign", "Verifier": "sign", "signer_for": "sign",
          "verifier_for": "sign"}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    # Lazy, so that `python -m saim_mesh.security.pki` does not import pki twice.
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
