"""Benchmarks: work-precision of the integrators and throughput of the simulator and
environments (``abb-gym bench accuracy`` and ``abb-gym bench speed``).  Speed targets live
here, never in timed unit tests."""
