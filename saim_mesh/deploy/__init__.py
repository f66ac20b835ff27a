"""Deploying the mesh across hosts (docs/deployment.md): one TOML file says which
host runs which routers, EAs, sources, consoles and TAK gateway (`file`), derived from
the task organization by default (`init`); each host starts its share under its own
supervisor (`launch`), with certificates naming the host's addresses (`certs`).
`mesh up` is the one-host case of the same launcher."""
