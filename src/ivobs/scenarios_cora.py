"""Benchmark systems from CORA (the MATLAB toolbox), shipped as scenarios (filled in below)."""
