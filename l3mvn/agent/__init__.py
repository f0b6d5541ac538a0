"""The agent side: everything that decides from observations alone, as habitat-baselines is to
habitat-lab. Perception, mapping, frontiers, planning, the language prior, the global policies and
the modular map agent (``modular``).

Nothing here imports the world side (``l3mvn.world``: scenes, simulator, task): an agent gets an
``EpisodeBrief`` and ``Observation``s and returns actions or ``Decision``s. ``tests/test_layers.py``
keeps it so.
"""
