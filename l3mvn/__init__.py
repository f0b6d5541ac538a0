"""L3MVN Studio: language-guided frontier exploration for ObjectNav, runnable anywhere."""

__version__ = "0.1.0"
