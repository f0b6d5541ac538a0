"""The local planner (spec "Local policy"); it plans on the agent's map, at its resolution."""

from __future__ import annotations

from dataclasses import dataclass

from l3mvn.core.errors import L3MVNError


@dataclass(frozen=True)
class PlannerConfig:
    """Local-policy constants (spec "Local policy"); distances in metres unless named ``_cells``."""

    # Obstacles grow by 1 cell, not the full agent radius (SemExp's disk(3)): maps' navmeshes
    # (SemExp channel 0) are already eroded by the radius, and the built-in world keeps walls 2 cells
    # from where the agent's centre may stand, so a 3-cell dilation closes real doorways of Gibson houses.
    obstacle_dilation_cells: int = 1
    # That growth lets the agent's centre run along the very edge of where it may stand, and a
    # heading up to 15 degrees off its path then grazes the wall, and many forward steps fail. So the
    # way to a goal keeps this many cells more from obstacles while the goal stays in reach so, and
    # falls back to the body's growth where it does not, or only by a detour longer than
    # ``clearance_detour_m`` (a 2-cell growth everywhere shuts narrow passages). Frontier costs and
    # reachability keep the body's growth.
    clearance_cells: int = 1
    clearance_detour_m: float = 1.0
    goal_dilation_m: float = 0.5
    # The short-term goal is the cell nearest the goal (geodesically) that the agent sees in a
    # straight free line within this distance; 0.25 m gives SemExp's ring.
    stg_lookahead_m: float = 1.0
    turn_threshold_deg: float = 15.0
    # Hysteresis: after a forward step that moved, the agent steps on while the short-term goal lies
    # within this angle of its heading and the step is free and downhill on the field; a turn still
    # aligns it within ``turn_threshold_deg``. 30 is one turn: either heading beside a path. It spends
    # path for steps (a step 30 degrees off gains 0.87 of one; a turn gains nothing), which pays
    # while the path bends again within ~7 steps, as house paths do (``steering``).
    keep_heading_deg: float = 30.0
    collision_threshold_m: float = 0.10
    # A failed forward step blocks a rectangle ahead of the agent: it starts this many cells ahead,
    # is this long, and this wide, widening by 2 cells per consecutive collision up to the maximum.
    collision_mark_offset_cells: int = 2
    collision_mark_length_cells: int = 3
    collision_mark_width_cells: int = 5
    collision_mark_max_width_cells: int = 9
    # Approaching the target, marks start one cell wide and widen to five (SemExp's own widths): the
    # floor round a toilet is tight, and a 5-9 cell mark laid after bumping into floor the navmesh lost
    # can close the only walkable passage beside it, just short of the success region.
    # Exploring keeps the wide marks: narrow ones there cost success in repeated collisions.
    collision_mark_target_width_cells: int = 1
    collision_mark_target_max_width_cells: int = 5
    # Even a 1-cell mark closes a passage only as wide as the agent (a toilet's floor the navmesh
    # eroded to 0.2 m), and the plan then leads metres round through the unknown while the target is
    # almost within reach. Approaching the target, marks
    # that lengthen the way to it by more than this are cleared, at most this many times an episode
    # (a real obstacle is bumped into again and marked again; the stuck signal still counts). Toward
    # any goal, the first failed step of a run whose rectangle lengthens the way so, and which swept
    # nearer a mapped obstacle, marks the free cells beside that obstacle instead where the plan
    # then turns off the failed heading (``planning.collisions``).
    target_mark_detour_m: float = 2.0
    target_mark_clears: int = 3
    # Stuck: this many collisions, or less than this displacement, within the last window of steps.
    stuck_window_steps: int = 50
    stuck_collisions: int = 20
    stuck_min_displacement_m: float = 0.5
    # Smallest margin of the planning window around agent and goal (it grows when a path needs it).
    window_margin_m: float = 2.0

    def __post_init__(self) -> None:
        positive = (
            "goal_dilation_m",
            "stg_lookahead_m",
            "turn_threshold_deg",
            "collision_threshold_m",
            "collision_mark_offset_cells",
            "collision_mark_length_cells",
            "collision_mark_width_cells",
            "collision_mark_target_width_cells",
            "stuck_window_steps",
            "stuck_collisions",
            "window_margin_m",
            "target_mark_detour_m",
        )
        for name in positive:
            if getattr(self, name) <= 0:
                raise L3MVNError(f"{name} must be positive, got {getattr(self, name)}")
        nonnegative = (
            "obstacle_dilation_cells",
            "clearance_cells",
            "clearance_detour_m",
            "stuck_min_displacement_m",
            "target_mark_clears",
        )
        bad = [n for n in nonnegative if not getattr(self, n) >= 0]
        if bad:
            raise L3MVNError(f"{', '.join(bad)} must be >= 0, got {', '.join(str(getattr(self, n)) for n in bad)}")
        for kind in ("", "target_"):
            first, widest = f"collision_mark_{kind}width_cells", f"collision_mark_{kind}max_width_cells"
            if getattr(self, widest) < getattr(self, first):
                raise L3MVNError(f"{widest} must be >= {first}")
        if self.stuck_collisions > self.stuck_window_steps:
            raise L3MVNError("stuck_collisions cannot exceed stuck_window_steps (it could never trigger)")
        if self.turn_threshold_deg >= 180:
            raise L3MVNError(f"turn_threshold_deg must be below 180, got {self.turn_threshold_deg}")
        if not self.turn_threshold_deg <= self.keep_heading_deg < 90:
            raise L3MVNError(
                f"keep_heading_deg must lie in [turn_threshold_deg ({self.turn_threshold_deg:g}), 90), "
                f"got {self.keep_heading_deg}"
            )
