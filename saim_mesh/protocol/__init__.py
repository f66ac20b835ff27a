"""What crosses the mesh: every message kind, the control messages, and the gate that checks each payload before use."""
