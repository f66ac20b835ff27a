"""Forward fusion: sensor hits become tracks close to the sensors (paper 3, 6.1)."""
from .kalman_node import KalmanNode
from .node import FusionNode

TRACKERS = ("window", "kalman")


def make_node(sc, group: str):
    """The fusion node of `group` for scenario `sc`: the Kalman tracker (default; each
    sensor's `sigma_m` is its noise) or the scan-window averager (`"tracker": "window"` in
    scenario.json's `fusion`; it never tracks a lone entity); `max_speed_mps` there bounds
    what a new track may be doing (ground sensors over ground units: a new track at 300 m/s
    would gather false alarms kilometres apart into a confirmed ghost). The runner and the fusion
    peer both build theirs here, so a mesh run and an in-process run fuse alike."""
    f = sc.meta.get("fusion") or {}
    kind = f.get("tracker", "kalman")
    if kind not in TRACKERS:
        raise ValueError(f"scenario {sc.name}: fusion.tracker {str(kind)[:40]!r} is not one of {', '.join(TRACKERS)}")
    if kind == "window":
        return FusionNode(group, sc.projection)
    sigma = {s["id"]: float(s["sigma_m"]) for s in f.get("sensors", ()) if "sigma_m" in s}
    opts = {}
    if "max_speed_mps" in f:   # the fastest target the sensors are there to track (its births' velocity prior)
        v = f["max_speed_mps"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v <= 1000 or v != v:
            raise ValueError(f"scenario {sc.name}: fusion.max_speed_mps must be a number in (0, 1000], got {str(v)[:40]!r}")
        opts["max_speed_mps"] = float(v)
    return KalmanNode(group, sc.projection, sigma, **opts)


__all__ = ["FusionNode", "KalmanNode", "TRACKERS", "make_node"]
