"""saim-mesh: execution monitoring of agent teams on an Eclipse Zenoh mesh."""
