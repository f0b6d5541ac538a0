"""The contract both sides share, and nothing else: errors, the typed records that cross the
simulator boundary (actions, poses, observations, episode briefs), the config tree, the camera model,
the category names, and small helpers (grids, paths, writing files whole).

Layering: ``core`` imports nothing of ours above it; the world side (``l3mvn.world``) and the agent side
(``l3mvn.agent``) import ``core`` and never each other; the run side (``l3mvn.run``) puts them together.
"""
