"""Every message kind the application knows, in one namespace: the shared codec
(`ea_agent.core.messages`), the alert, and each domain's messages (importing a
domain's message module registers its kinds with the codec)."""
from __future__ import annotations

from ea_agent.core.messages import (MESSAGE_TYPES, VERSION, Decoder, Message, MessageError, decode, encode,  # noqa: F401
                                    from_dict, register, to_dict)
from ea_agent.core.alert import PRIORITIES, Alert  # noqa: F401
from ea_agent.domains.suo.messages import (CallForFire, CallForFireConfirm, LocationReport, MissionConfirm,  # noqa: F401
                                           Order, Reorganization, SensorHit, SensorTrack)
from ea_agent.domains.uv.messages import UvAgent, UvSighting, UvState  # noqa: F401
