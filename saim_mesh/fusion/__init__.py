"""Forward fusion: sensor hits become tracks close to the sensors (paper 3, 6.1)."""
from .kalman_node import KalmanNode
from .node import FusionNode

TRACKERS = ("window", "kalman")


def make_node(sc, group: str):
    """The fusion node of `group` for scenario `sc`: the scan-window averager (default)
    or the Kalman tracker (`"tracker": "kalman"` in scenario.json's `fusion`, which then
    takes each sensor's `sigma_m`). The runner and the fusion peer both build theirs
    here, so a mesh run and an in-process run fuse alike."""
    f = sc.meta.get("fusion") or {}
    kind = f.get("tracker", "window")
    if kind not in TRACKERS:
        raise ValueError(f"scenario {sc.name}: fusion.tracker {str(kind)[:40]!r} is not one of {', '.join(TRACKERS)}")
    if kind == "window":
        return FusionNode(group, sc.projection)
    sigma = {s["id"]: float(s["sigma_m"]) for s in f.get("sensors", ()) if "sigma_m" in s}
    return KalmanNode(group, sc.projection, sigma)


__all__ = ["FusionNode", "KalmanNode", "TRACKERS", "make_node"]
