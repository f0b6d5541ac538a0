"""Agent-level constants: when to re-select, stop, give up, look (spec "Choosing the long-term
goal", "Lessons"). Checks that span sections (against the frontier distances, the success distance,
the turn angle) live in ``Config``."""

from __future__ import annotations

from dataclasses import dataclass

from l3mvn.core.errors import L3MVNError


@dataclass(frozen=True)
class AgentConfig:
    """Agent-level constants (spec: "Choosing the long-term goal", "Lessons")."""

    map_input_height: int = 120
    map_input_width: int = 160
    replan_every: int = 10  # num_local_steps: re-select the long-term goal this often
    look_around_steps: int = 12  # an initial 360-degree turn (12 x 30 deg): the first map shows all round the start
    target_min_cells: int = 4  # cells of the goal channel before the target counts as seen
    stop_distance_m: float = 0.9  # stop when the mapped target is this close (success needs < 1.0 m)
    # When no path leads closer (unreachable, or stuck against what the map does not show), stop
    # this close: the mapped cells are the surfaces seen, so the object reaches at least that near.
    blocked_stop_distance_m: float = 0.95
    # Goal cells too few to stop at are approached to this distance; still too few then: rejected.
    candidate_reached_m: float = 0.9
    target_escapes: int = 2  # escapes tried for an unreachable target before it is set aside
    frontier_reached_m: float = 0.75  # >= the 0.5 m minimum frontier distance (no dead zone)
    commitment_margin: float = 0.15  # keep the current frontier unless another scores this much higher
    # ... and the current frontier is the new list's frontier nearest to it within this distance
    # (farther: it is gone, and the new choice stands).
    commitment_radius_m: float = 1.0
    # Escape: after this many steps with the goal unreachable (usually walled in by its own
    # collision marks) or a stuck signal, clear the marks and wiggle out with random turns.
    escape_after_unreachable: int = 3
    # Exploration goals (frontiers, sampled cells, manual cells) are approached with this small goal
    # disk, not the object's 0.5 m one: that one reaches through walls, so a frontier in the next
    # room would read as "reached" from this side and the agent would push into the wall.
    explore_goal_dilation_m: float = 0.1
    # A reached or unreachable exploration goal blocks frontiers whose centre lies this close to it ...
    blocked_radius_m: float = 1.0
    # ... and, where the goal was a frontier, only those that come this close to that frontier's own
    # cells: the rest of what the radius covers borders other unknown space (an opening beside the
    # spot, a hallway the goal never faced), and blocking it would shut that space for good.
    blocked_frontier_gap_m: float = 0.25
    max_reselect: int = 3  # exploration goals tried within one step before walking on
    # An exploration goal the agent has not come goal_progress_m closer to in this many steps is given up like
    # an unreachable one: a path through unknown space that keeps meeting new walls stays "reachable"
    # while the agent circles (a policy that keeps its goal, random sample, would circle for hundreds of steps).
    goal_patience_steps: int = 40
    goal_progress_m: float = 0.5  # ... "closer" means by at least this much
    # ... and a walk that maps this much new floor meanwhile is progressing too: a detour round walls
    # it could not see lengthens the planned way for a while, but it is not circling.
    goal_progress_area_m2: float = 2.0
    # Reaching a goal is not seeing it: an exploration goal or a glimpsed target counts as looked at
    # only once it lies within this angle of the view's centre (the 79-degree view's half is 39.5).
    # Without it a frontier at a door reads as reached from beside the door, is blocked, and the
    # room behind it (a bathroom and its toilet) is never looked into.
    look_tolerance_deg: float = 30.0
    # ... and a frontier that still borders unknown space once faced is walked up to this close.
    frontier_press_m: float = 0.3
    # With no frontier left, areas explored only from afar (the floor of a room seen through its
    # door) at least this large are visited before wandering at random (MapConfig.look_distance_m).
    look_min_area_m2: float = 0.25
    # A glimpsed target that stays under target_min_cells once approached and faced is looked at
    # from this many other poses, this far from it (valid depth starts at 0.5 m), before set aside.
    candidate_views: int = 2
    viewpoint_min_m: float = 1.2
    viewpoint_max_m: float = 1.8
    # The goal filling this share of the (mapped) frame beyond the depth range (no depth, so no map
    # cells) is a sighting worth walking towards: a goal far down a corridor may show as a small blob
    # for only a step or two, and the agent would turn away from it for good. Larger blobs without
    # depth are too near.
    glimpse_min_fraction: float = 0.001
    glimpse_max_fraction: float = 0.05

    def __post_init__(self) -> None:
        if self.map_input_height < 1 or self.map_input_width < 1:
            raise L3MVNError(
                f"map_input_height and map_input_width must be >= 1, got {self.map_input_height}x{self.map_input_width}"
            )
        if self.replan_every < 1 or self.target_min_cells < 1 or self.goal_patience_steps < 1:
            raise L3MVNError("replan_every, target_min_cells and goal_patience_steps must be >= 1")
        if not (self.commitment_radius_m > 0 and self.goal_progress_m > 0):
            raise L3MVNError("commitment_radius_m and goal_progress_m must be positive")
        if not 0 < self.stop_distance_m <= self.blocked_stop_distance_m:
            raise L3MVNError("stop distances must satisfy 0 < stop_distance_m <= blocked_stop_distance_m")
        if not 0 < self.look_tolerance_deg < 90.0:
            raise L3MVNError(f"look_tolerance_deg must lie in (0, 90), got {self.look_tolerance_deg}")
        counts = {
            "look_around_steps": self.look_around_steps,
            "target_escapes": self.target_escapes,
            "max_reselect": self.max_reselect,
            "candidate_views": self.candidate_views,
        }
        if bad := {k: v for k, v in counts.items() if v < 0}:
            raise L3MVNError(f"{', '.join(bad)} must be >= 0, got {', '.join(map(str, bad.values()))}")
        if self.escape_after_unreachable < 1:
            raise L3MVNError(f"escape_after_unreachable must be >= 1, got {self.escape_after_unreachable}")
        lengths = {"blocked_radius_m": self.blocked_radius_m, "candidate_reached_m": self.candidate_reached_m}
        if nonpositive := {k: v for k, v in lengths.items() if not v > 0}:
            raise L3MVNError(
                f"{', '.join(nonpositive)} must be positive, got {', '.join(map(str, nonpositive.values()))}"
            )
        if (
            self.look_min_area_m2 < 0
            or self.commitment_margin < 0
            or self.explore_goal_dilation_m < 0
            or self.blocked_frontier_gap_m < 0
            or self.goal_progress_area_m2 < 0
        ):
            raise L3MVNError(
                "look_min_area_m2, commitment_margin, explore_goal_dilation_m, blocked_frontier_gap_m and "
                "goal_progress_area_m2 must be >= 0"
            )
        if not 0 < self.frontier_press_m < self.frontier_reached_m:
            raise L3MVNError("frontier_press_m must satisfy 0 < frontier_press_m < frontier_reached_m")
        if not 0 < self.glimpse_min_fraction < self.glimpse_max_fraction <= 1:
            raise L3MVNError("glimpse fractions must satisfy 0 < glimpse_min_fraction < glimpse_max_fraction <= 1")
        if not 0 < self.viewpoint_min_m < self.viewpoint_max_m:
            raise L3MVNError("viewpoint distances must satisfy 0 < viewpoint_min_m < viewpoint_max_m")

    def downsample_factor(self, height: int, width: int) -> int:
        """The stride frames of this size are mapped at (SemExp: 480x640 -> 120x160 with 4)."""
        factor = max(1, height // self.map_input_height)
        if height % factor or width % factor:
            raise L3MVNError(
                f"frame {height}x{width} is not divisible by the mapper's downsample factor {factor} "
                f"(height // {self.map_input_height}): choose e.g. 480x640 or 120x160"
            )
        return factor
