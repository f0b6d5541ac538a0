"""Scene audit: can an agent confirm every goal object the way the success rule needs it to?

An episode only succeeds if the agent, standing in the goal's success region, has *mapped* the goal
well enough for its own confirmation rule. Gaps in the simulated world (an object with no floor near
it, walled in, lost by the world builder, too thin to map) cap the success rate of every policy, so
they are measured here, per goal instance, with the agent's own pieces: the renderer, the agent's
``Perception`` (ground-truth labels: segmentation errors are the agent's, not the world's) and its
``TargetSearch.mask``.

For each instance (8-connected component of a goal category's footprint) the audit stands the agent
on a bounded, deterministic sample of walkable cells in the instance's success region (the rule of
``TaskConfig.success_rule``), looks around (``AuditConfig.headings`` x ``tilts_deg``), maps those
views into a fresh map and asks the agent's rule whether the mapped cells on or near this instance
confirm it. Poses are tried nearest first and the first confirming one ends the search; failing
that, reachable poses outside the region (up to ``search_radius_m``) give the nearest distance from
which it can be confirmed at all. Every instance that is not confirmable gets one reason from
``REASONS``.

Modules: ``records`` (settings, reasons, records, the JSON report), ``looking`` (one pose looked
around from), ``floor`` (the instances and episodes of one floor), ``split`` (a split over worker
processes), ``report`` (the text table and diagnostic pictures).
"""

from l3mvn.run.audit.floor import FloorAuditor, audit_floor
from l3mvn.run.audit.records import REASONS, AuditConfig, AuditReport, EpisodeAudit, FloorAudit, InstanceAudit
from l3mvn.run.audit.report import format_report, write_diagnostic_png
from l3mvn.run.audit.split import audit_scenes, audit_split, load_split_for_audit

__all__ = [
    "REASONS",
    "AuditConfig",
    "InstanceAudit",
    "EpisodeAudit",
    "FloorAudit",
    "AuditReport",
    "FloorAuditor",
    "audit_floor",
    "audit_scenes",
    "audit_split",
    "load_split_for_audit",
    "format_report",
    "write_diagnostic_png",
]
