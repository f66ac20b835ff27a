"""What an EA writes down: its alerts, notices and commands as durable JSON lines, and where alerts are shown."""
