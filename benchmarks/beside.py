"""The in-process baseline measured *while* the live mesh runs, on a thread of the
benchmark's own process: the same two vCPUs at the same moment as the peers. This
machine's speed moves by up to 2x from minute to minute, so a baseline taken after the
mesh (bench_mesh's `in_process_cpu_us_per_event`) can be measured in another mood than
the peers were; this one cannot, and it shares their contention (caches, preemption).
Both are reported; the issue's `ea_cpu_ratio` stays the one against the quiet baseline."""
from __future__ import annotations

import threading


class InProcessBeside(threading.Thread):
    """Each unit's EA on exactly the messages its peer gets, one unit after another, round
    after round, until `stop()`; `done` holds (thread CPU s, messages) per unit of the runs
    that ended before the stop (a run cut by it is not counted)."""

    def __init__(self, sc, units: list[str], streams: dict[str, list]):
        super().__init__(name="in-process-beside", daemon=True)
        self.sc, self.units, self.streams = sc, units, streams
        self._halt = threading.Event()
        self.done: dict[str, list] = {}

    def stop(self) -> None:
        self._halt.set()
        self.join()

    def run(self) -> None:
        from .mesh import same_input_run
        i = 0
        while not self._halt.is_set():
            u = self.units[i % len(self.units)]
            i += 1
            got = same_input_run(self.sc, u, self.streams, self._halt.is_set)
            if got is None or self._halt.is_set():
                return   # cut by the stop, or ended after it: not counted
            cpu, ea = got
            acc = self.done.setdefault(u, [0.0, 0])
            acc[0] += cpu
            acc[1] += ea.n_in

    def ratio(self, peers: dict[str, dict]) -> dict:
        """The peers' main-loop CPU per message against this baseline's, over the units it
        finished (the peers of those units only: CPU per message differs by unit)."""
        units = [u for u in self.done if u in peers and peers[u].get("messages")]
        if not units:
            return {"same_time_units": [], "in_process_same_time_cpu_us_per_event": None,
                    "ea_cpu_us_per_event_same_units": None, "ea_cpu_ratio_same_time": None}
        ip = 1e6 * sum(self.done[u][0] for u in units) / sum(self.done[u][1] for u in units)
        ea = 1e6 * sum(peers[u]["thread_cpu_s"] for u in units) / sum(peers[u]["messages"] for u in units)
        return {"same_time_units": sorted(units), "in_process_same_time_cpu_us_per_event": round(ip, 2),
                "ea_cpu_us_per_event_same_units": round(ea, 2), "ea_cpu_ratio_same_time": round(ea / ip, 3)}
