"""Field logs: reading and writing runs, checks, repairs, the simulator, the positioning
pipeline and audits."""
