"""Global policies (which long-term goal the map-based agent walks to) and the ground-truth baselines;
``l3mvn.registry`` builds any of them by name."""
