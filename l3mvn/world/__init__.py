"""The world side: what the agent acts in and what judges it, as habitat-lab is to its baselines.

Scenes (top-down semantic floors), the simulator that moves and renders (``sim``, behind the
``Environment`` contract), the task that judges (``task``: success regions, measures, scoring),
episodes and datasets, and the baselines that read ground truth (``baselines``: the shortest-path
oracle, the frontier oracle's ground-truth reader, the random walk). Nothing here imports the agent side.
"""
