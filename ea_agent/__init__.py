"""Execution Assistant: plan, mission model, monitors, alert detection and VOI/VOA.

`ea_agent.core` is domain independent; `ea_agent.domains.suo` holds the small-unit
operations knowledge (missions, detectors, VOA heuristics).
"""
