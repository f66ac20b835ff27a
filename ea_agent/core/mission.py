"""The root of every domain's mission model (paper 6.5): a class hierarchy whose
methods say how a mission is monitored. The EA calls these methods; they post
monitors back through `ctx`, the domain's monitoring API, as the paper's methods
post facts. A domain subclasses `Mission`, adds its own methods and registers its
leaf classes in a `Registry`."""
from __future__ import annotations

from typing import Any, ClassVar

from .plan import MissionSpec


class Mission:
    """Every mission has start and end time constraints and a place to be."""
    TYPE: ClassVar[str] = "mission"
    PARAMS: ClassVar[dict[str, str]] = {   # name -> one line; merged along the hierarchy (all_params)
        "voi": "optional per-mission VOI overrides, e.g. {schedule_s: 10}",
    }
    REQUIRED: ClassVar[tuple[str, ...]] = ()
    UNIT_PARAMS: ClassVar[tuple[str, ...]] = ()       # params that name units (their messages are needed)
    DEFAULT_PRIORITY: ClassVar[dict[str, str]] = {}   # the domain's alert type -> priority
    PRIORITY: ClassVar[dict[str, str]] = {}           # per-mission overrides
    AUTO_START: ClassVar[bool] = False                # executed by the EA itself (no confirmation)
    LINE_PARAMS: ClassVar[tuple[str, ...]] = ()       # geometry params that must be lines
    CHECKS: ClassVar[tuple[str, ...]] = ("start and end time constraints (Fig. 6)",)   # what it monitors

    @classmethod
    def check_params(cls, params: dict, overlay: dict) -> tuple[str, str] | None:
        """A class-specific problem with `params` (against the overlay's control measures) as
        (field, why), or None; `validate` reports it."""
        return None

    def __init__(self, spec: MissionSpec):
        self.spec = spec
        self.id = spec.id
        self.unit = spec.unit
        self.params: dict[str, Any] = spec.params

    @classmethod
    def all_params(cls) -> dict[str, str]:
        out: dict[str, str] = {}
        for k in reversed(cls.__mro__):
            out.update(getattr(k, "PARAMS", {}) if "PARAMS" in vars(k) else {})
        return out

    @classmethod
    def unknown_params(cls, params: dict) -> list[str]:
        """The keys of `params` that no class along the hierarchy declares in PARAMS: a
        loader rejects them, so that nothing a plan says is silently ignored (a class
        declares every parameter it, its monitors or its detectors read)."""
        known = cls.all_params()
        return [k for k in params if k not in known]

    @classmethod
    def required(cls) -> tuple[str, ...]:
        out: list[str] = []
        for k in reversed(cls.__mro__):
            out += [p for p in vars(k).get("REQUIRED", ()) if p not in out]
        return tuple(out)

    def __repr__(self) -> str:
        return f"<{self.TYPE} {self.id} by {self.unit}>"

    # -- the monitoring API (paper 6.5) ----------------------------------------------
    def post_execution_constraints(self, ctx) -> None:
        """Main entry: post every constraint this mission wants enforced."""
        self.start_time_constraints(ctx)
        self.end_time_constraints(ctx)
        self.location_constraints(ctx)

    def start_time_constraints(self, ctx) -> None:
        ctx.post_time_constraint(self, "start", self.spec.start)

    def end_time_constraints(self, ctx) -> None:
        ctx.post_time_constraint(self, "end", self.spec.end)

    def location_constraints(self, ctx) -> None:
        """Where the unit must be while executing; the root class expects nothing."""

    def check_initial_location(self, ctx, t: float) -> None:
        """At mission start; most missions accept any start position."""

    def check_final_location(self, ctx, t: float) -> None:
        """At mission end; the root class has no destination."""

    def contingency_satisfied(self, ctx) -> bool:
        return False

    def execute_mission(self, ctx, t: float) -> None:
        """Missions carried out by people need nothing from the EA."""

    def compute_priority(self, alert_type: str) -> str:
        """The mission's own priority for the type, else the EA's default (`defaults`: the
        domain's table, overridden by the EA's configuration), else PRIORITY."""
        return self.PRIORITY.get(alert_type, self.defaults.get(alert_type, "priority"))

    @property
    def defaults(self) -> dict[str, str]:
        return self.__dict__.get("_defaults", self.DEFAULT_PRIORITY)

    def use_defaults(self, table: dict[str, str]) -> "Mission":
        self.__dict__["_defaults"] = table
        return self


class Registry(dict):
    """Leaf mission classes by their `TYPE`; `leaf` is the class decorator."""

    def leaf(self, cls: type[Mission]) -> type[Mission]:
        if cls.TYPE in self and self[cls.TYPE] is not cls:
            raise ValueError(f"mission type {cls.TYPE!r} registered twice")
        self[cls.TYPE] = cls
        return cls

    def make(self, spec: MissionSpec) -> Mission:
        return self[spec.type](spec)
