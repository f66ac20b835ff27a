"""Starting and supervising the mesh's processes: child processes and their logs, the EA fork server, Zenoh configuration."""
