"""PONI's potential functions (Ramakrishnan et al., CVPR 2022) on the agent's own map: a network reads
the partial semantic map and predicts, at every cell, how much unexplored floor lies beyond it (the
area potential) and how near each goal is (the object potentials). The policy reads them at the
frontiers. Training data comes from full house maps, then from a prior-free agent's walks on them
(``l3mvn.run.potentials``)."""

from l3mvn.agent.potentials.features import CHANNELS, OUTPUTS, WindowGrid, objects_hot, window_features
from l3mvn.agent.potentials.model import PotentialModel, PotentialNet, shipped_checkpoint
from l3mvn.agent.potentials.policy import PotentialPolicy, expected_totals

__all__ = [
    "CHANNELS",
    "OUTPUTS",
    "PotentialModel",
    "PotentialNet",
    "PotentialPolicy",
    "WindowGrid",
    "shipped_checkpoint",
    "expected_totals",
    "objects_hot",
    "window_features",
]
