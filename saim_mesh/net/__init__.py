"""Routing and links: Zenoh routers per command post (`router`), the topology that says
which exist and who attaches where (`topology`), starting them with emulated radio links
(`routed`), and the link emulator itself (`linkemu`)."""
