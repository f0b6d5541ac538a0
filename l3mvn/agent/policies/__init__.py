"""Global policies: which long-term goal the map-based agent walks to (nearest frontier,
cost-utility, random sample, language-scored, the frontier oracle); ``l3mvn.run.registry`` builds
them by name."""
