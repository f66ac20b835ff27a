"""Benchmarks, kept out of the runtime package: each writes its figures as JSON under
bench/results/ (scripts/bench_*). None of the mesh's processes imports them."""
