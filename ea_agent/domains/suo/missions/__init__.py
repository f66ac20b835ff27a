"""The SUO mission model (paper 6.5): a class hierarchy whose methods say how each
mission is monitored. The EA calls these methods; they post monitors back to the
EA through `ctx` (the domain's monitoring API), as the paper's methods post facts.

Non-leaf classes: MovementMission, OffensiveMission, PositionMission,
SecurityMission, CoordinationMission, ContingentMission, ReorganizationMission.
Leaf classes carry Army doctrine names (FM 3-90) in `TYPE`.
"""
from __future__ import annotations

from .base import DEFAULT_PRIORITY, REGISTRY, Mission, mission
from .contingent import Branch, ContingentMission, Reorganize, ReorganizationMission, Sequel
from .coordination import CoordinationMission, LinkUp, PassageOfLines, ReliefInPlace
from .movement import (Bypass, Delay, FollowAndAssume, FollowAndSupport, FollowMission, Move, MovementMission,
                       MovementToContact, RouteReconnaissance, TacticalRoadMarch, Withdraw)
from .offensive import (Attack, Breach, Clear, Destroy, Fix, HastyAttack, Isolate, OffensiveMission, Secure,
                        Seize)
from .position import (AttackByFire, Block, Contain, Defend, Disrupt, Occupy, Overwatch, PositionMission, Retain,
                       Suppress, SupportByFire)
from .security import AreaReconnaissance, Guard, Observe, Screen, SecurityMission, ZoneReconnaissance

make = REGISTRY.make

__all__ = ["DEFAULT_PRIORITY", "REGISTRY", "Mission", "mission", "make", "MovementMission", "FollowMission",
           "OffensiveMission", "PositionMission", "SecurityMission", "CoordinationMission", "ContingentMission",
           "ReorganizationMission", *sorted(c.__name__ for c in REGISTRY.values())]
