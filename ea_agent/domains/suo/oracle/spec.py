"""What the oracle holds the EAs to: the scenario's statement of what is worth knowing
(SPEC), the tolerances of what sensors and reports can tell, and how the paper and
doctrine judge each mission type. Constants only, and the two small helpers every
part of the truth uses."""
from __future__ import annotations

# What the commander said is worth knowing (the paper's scenario, 6.8); plans may
# override per mission (params.voi). Fixed here: the EAs read theirs from their config.
SPEC = {"out_of_position_m": 150.0, "schedule_s": 30.0, "unknown_position_s": 120.0,
        "weapons_range_m": 1000.0, "threat_radius_m": 2000.0, "coordination_radius_m": 300.0,
        "ahead_m": 1500.0, "ahead_width_m": 300.0,   # a unit is at a checkpoint this near its point:
        "checkpoint_m": 50.0, "standoff_m": 1000.0, "lift_m": 500.0,
        # a zone/area reconnaissance sees a cell of this grid once a member is this near its
        # centre; it is behind when the share seen trails the share of its time gone by
        # `recon_lag`, and incomplete below `recon_complete` at its end
        "recon_cell_m": 250.0, "recon_sight_m": 400.0, "recon_lag": 0.25, "recon_complete": 0.9}   # a moving unit's commander wants to know of hostiles
                                                     # this far ahead on its route, this near it
EPISODE_S = 720.0   # the paper's alert expiry (12 min): a threat back near a platoon, or a group back
                    # in a watched area, after this long away is news again
CLOSER = 2.0        # the nearest threat at half the distance of the last incident: a new one
STRONGER = 2.0      # the threats near a platoon twice as strong as at the last incident
MATERIAL = 1.25     # an alert counts for such an incident once the change reached this step
TOLERANCE_M = 200.0  # how well sensors place a hostile group (5 sigma of the scenario's 25-40 m)
CONFIRM_S = (0.0, 5.0, 10.0)   # a track is confirmed after 3 sensor scans (5 s apart) of it
REACH_M = 85.0      # a group's members stand up to this far from its centre (the sensors see members)
RESOLVE_M = 150.0   # groups nearer than this are one to any sensor of the scenario (sigma 25-40 m)
NO_VALUE_S = 90.0   # the paper (5): a hostile alert of the same type about the same unit has no
                    # value this long after the last; a change inside it is told when it ends

# How the paper judges a unit on each mission type (6.5): where its members must be
# (the rule: its centroid, any member, or all of them) and by which geometry.
ANY_RULE = {"area-reconnaissance", "guard", "link-up", "observe", "overwatch", "passage-of-lines",
            "relief-in-place", "route-reconnaissance", "screen", "zone-reconnaissance"}
FINAL_RULE = {"attack": "all", "clear": "all", "secure": "all", "seize": "all", "breach": "any",
              "destroy": "centroid", "fix": "centroid", "hasty-attack": "centroid", "isolate": "centroid"}
OBJECTIVE = {"attack", "breach", "clear", "destroy", "fix", "hasty-attack", "isolate", "secure", "seize"}
ROUTE = {"bypass", "delay", "follow-and-assume", "follow-and-support", "move", "movement-to-contact",
         "route-reconnaissance", "tactical-road-march", "withdraw"}
AREA = {"area-reconnaissance", "guard", "observe", "screen", "zone-reconnaissance"}   # position + area
RECON = {"area-reconnaissance", "zone-reconnaissance"}   # progress through the area by its time
COORDINATION = {"link-up", "passage-of-lines", "relief-in-place"}
CONTINGENT = {"branch", "sequel"}
REORGANIZATION = {"reorganize"}
AUTO_START = REORGANIZATION   # the EA executes it itself at its start time
LIFE = {"contact", "fratricide", "call-for-fire"}   # life-threatening: the paper's flash alerts
# What doctrine (FM 3-90) says each task forbids the enemy: to enter the held place (retain, guard,
# secure: the objective while it runs; a defence's rear line; a block: the area or line it names,
# whichever the plan gives), to leave it (fix, isolate, destroy: the objective; contain: the
# engagement area), to be left on the objective at the end (clear, destroy). Seize asks only that
# its own elements be on the objective (by its `by`, and at its end).
PENETRATION = {"block": ("area", "line"), "retain": ("position",), "guard": ("area",), "defend": ("rear_line",),
               "secure": ("objective",)}
ESCAPE = {"fix": "objective", "isolate": "objective", "destroy": "objective", "contain": "engagement_area"}
END_STATE = {"clear", "destroy"}
SUPPRESS = {"suppress"}   # fires on `target` through `window`: the target within weapons range
DISRUPT = {"disrupt"}     # from `by`, no group on `avenue` still advancing along it faster than `tempo_mps`
TEMPO_MPS = 1.0           # a disrupt's default tempo
TEMPO_TREND_S = 60.0      # a group's advance along the avenue is measured over this long
ZONE = {"zone-reconnaissance"}   # progress is the depth passed front to rear (area: the share seen)
ASSUME = {"follow-and-assume"}   # takes over the supported unit's mission when it halts
HALT_S = 180.0            # a follow-and-assume's default: the supported unit standing this long has halted
HALT_M = 50.0             # ... standing: its centroid within this of one place
FOLLOW = {"follow-and-support", "follow-and-assume"}
STANDOFF = {"screen", "bypass", "withdraw", "delay"}   # not to become decisively engaged   # stay within a distance band of the supported unit
FOLLOW_MAX_M = 3000.0   # the band's far edge unless the plan says (band_m)
FRIENDLY_MPS = 6.0      # the fastest a friendly unit moves (how far a stale report can be off)
LINE_MARGIN_M = 50.0    # a unit is across a line this far beyond it (the plan's statement)
FRIENDLY_ERR_M = 100.0  # how far the EA's picture of a moving friendly unit may be off (reports' age, noise)
CORRIDOR_BACK_M = 300.0  # a corridor reaches this far behind where the unit started (its start is an estimate)
APPROACH_M = 1000.0     # a group this near an area no hostile may enter may be projected to enter it


def geometry_params(typ: str) -> tuple[str, ...]:
    if typ in OBJECTIVE:
        return ("objective", "axis")
    if typ in ROUTE:
        return ("route", "destination")
    if typ in AREA:
        return ("position", "area")
    if typ in COORDINATION:
        return ("point",)
    if typ in CONTINGENT | REORGANIZATION:
        return ()
    return ("position", "engagement_area")


TICK = 5.0
TRACK_S = 10.0      # and one hostile track period: the slack of friendly-position incidents
PROX = ["contact", "distance", "strength", "proximity"]


def _bands(geom):
    """An area grown and shrunk by TOLERANCE_M: where a group may be told to be in it, and
    where it must be (the area itself when it is too small to shrink)."""
    deep = geom.buffer(-TOLERANCE_M)
    return geom.buffer(TOLERANCE_M), (geom if deep.is_empty else deep)


def _runs(ts: list[float]) -> list[tuple[float, float]]:
    """Consecutive tick times -> [(first, last)] intervals."""
    out: list[list[float]] = []
    for t in ts:
        if out and t - out[-1][1] <= TICK + 1e-6:
            out[-1][1] = t
        else:
            out.append([t, t])
    return [(a, b) for a, b in out]

