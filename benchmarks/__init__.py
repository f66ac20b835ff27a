"""Benchmarks, kept out of the runtime package: each writes its figures as JSON under
bench/results/ (scripts/bench_*). None of the mesh's processes imports them."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]   # the repository: scenarios read, bench/results/ written
RESULTS = ROOT / "bench" / "results"
