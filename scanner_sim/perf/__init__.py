"""Speed measurements: the end-to-end bench, the ray stage against raw Embree, and the CPU profile per stage."""
