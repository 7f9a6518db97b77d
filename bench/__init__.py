"""Benchmarks: each ``bench/bench_<area>.py`` defines ``run(quick: bool) -> list[Row]``."""
