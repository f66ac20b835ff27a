"""Interest groups and Zenoh key expressions (by mission, geography and command).

Not built yet: it arrives with the mesh issue. Nothing here is used by the EA core.
"""
