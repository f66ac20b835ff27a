"""CoT type codes and their MIL-STD-2525B symbol codes: what a TAK client draws.

A CoT type is `a-<affiliation>-<dimension>-<function...>` for things (atoms), `b-...` for
bits (alerts, markers), `u-d-...` for drawn shapes. TAK derives the 2525 icon from it;
the echelon is not part of a CoT type, so it travels as the 15-character 2525B SIDC in
our own detail (`__saim sidc=...`) and in the callsign."""
from __future__ import annotations

import re

FRIENDLY_UNIT = "a-f-G-U-C"          # friendly ground combat unit (ATAK's own PLI type)
FRIENDLY_ENTITY = "a-f-G-U-C-I"      # one friendly entity: infantry (a soldier or a team)
HOSTILE_TRACK = "a-h-G-U-C"          # hostile ground combat unit (a fused track)

EMERGENCY = "b-a-o-tbl"              # ATAK "911 Alert": the red emergency banner and sound
CONTACT = "b-a-o-opn"                # ATAK "Troops In Contact" emergency
CANCEL = "b-a-o-can"                 # ATAK "cancel alert": the emergency with the same uid is over
GEOFENCE = "b-a-g"                   # geofence breached (linked to the shape it is about)
MARKER = "b-m-p-s-m"                 # a spot map marker with a colour and remarks
SHAPE = "u-d-f"                      # freehand line / closed polygon (<link point=.../>)
CIRCLE = "u-d-c-c"                   # circle (<shape><ellipse .../></shape>)
DELETE = "t-x-d-d"                   # tells clients to drop the linked uid

EMERGENCY_NAMES = {EMERGENCY: "911 Alert", CONTACT: "Troops In Contact"}

# 2525B echelon character (SIDC position 12) of the SUO task organization's unit kinds
ECHELON = {"team": "A", "squad": "B", "section": "C", "platoon": "D", "company": "E",
           "battalion": "F", "regiment": "G", "brigade": "H", "division": "I"}

# `how`: m-g GPS (an entity's report), m-f fused (a unit centroid, a fused track, an alert)
HOW_GPS, HOW_FUSED = "m-g", "m-f"

# shape colours (ARGB as signed 32-bit ints, the way TAK writes them)
COLOURS = {"black": -16777216, "blue": -16776961, "red": -65536, "green": -16711936,
           "yellow": -256, "orange": -23296, "white": -1, "grey": -8355712}
OVERLAY_COLOUR = {"boundary": "black", "phase-line": "blue", "objective": "blue", "battle-position": "blue",
                  "assembly-area": "blue", "engagement-area": "red", "area": "grey", "route": "green",
                  "avenue-of-approach": "red", "decision-point": "yellow", "checkpoint": "blue", "nai": "yellow"}
PRIORITY_COLOUR = {"flash": "red", "immediate": "orange", "priority": "yellow", "routine": "white"}

_TYPE = re.compile(r"^[abtuyc](-[A-Za-z0-9.*_]{1,16}){0,12}$")


def valid_type(t: str) -> bool:
    """A syntactically possible CoT type (`a-f-G-U-C`, `b-a-o-tbl`, `u-d-f`, ...)."""
    return bool(_TYPE.match(t)) and len(t) <= 96


def affiliation(t: str) -> str | None:
    """'f', 'h', 'n', 'u', ... for atoms (`a-<aff>-...`), None for other events."""
    parts = t.split("-")
    return parts[1] if parts[0] == "a" and len(parts) > 1 else None


def sidc(cot_type: str, echelon: str | None = None, hq: bool = False) -> str:
    """The 15-character MIL-STD-2525B SIDC of an atom's CoT type, with the echelon
    modifier: `a-f-G-U-C` + platoon -> `SFGPUC-----D---` (`-` fills unknown places)."""
    parts = cot_type.split("-")
    if parts[0] != "a" or len(parts) < 3:
        raise ValueError(f"no 2525 symbol for CoT type {cot_type!r}")
    aff, dim, fn = parts[1].upper(), parts[2].upper(), "".join(parts[3:]).upper()
    mod = ("A" if hq else "-") + ECHELON.get(echelon or "", "-")
    return f"S{aff}{dim}P{fn[:6]:-<6}{mod}---"[:15].ljust(15, "-")
