"""The navigation loop, one step at a time: environment + policy -> StepEvents on a bus.

The evaluator runs a session to the end; the dashboard steps one interactively, can change the target
mid-episode (a new, clearly marked segment) and hand the policy a manual long-term goal.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import replace

import numpy as np

from l3mvn.errors import L3MVNError
from l3mvn.eval.metrics import EpisodeOutcome, EpisodeResult, score_episode
from l3mvn.events import Decision, EventBus, StepEvent
from l3mvn.sim.simulator import BuiltinSimulator
from l3mvn.sim.types import Action, Episode, Observation

# The target counts as seen once this fraction of a frame shows it with valid depth.
SEEN_FRACTION = 0.001
COLLISION_WINDOW = 50


def target_visible(obs: Observation) -> bool:
    visible = np.count_nonzero((obs.semantic == obs.goal_id) & (obs.depth > 0))
    return visible >= SEEN_FRACTION * obs.semantic.size


class EpisodeSession:
    """Drives one episode. Policies return an Action or a Decision (map-based agents explain
    themselves); every step is published on ``bus`` as a StepEvent."""

    def __init__(self, env: BuiltinSimulator, policy, *, policy_name: str, config_hash: str,
                 bus: EventBus | None = None) -> None:
        self.env, self.policy = env, policy
        self.policy_name, self.config_hash = policy_name, config_hash
        self.bus = bus or EventBus()
        self.episode: Episode | None = None
        self.segment = 0
        self.last_event: StepEvent | None = None
        self._result: EpisodeResult | None = None

    # --- lifecycle ---------------------------------------------------------------------------
    def start(self, episode: Episode) -> StepEvent:
        self._t0 = time.perf_counter()
        self.episode, self.segment, self._result = episode, 0, None
        obs = self.env.reset(episode)
        self.policy.reset(episode)
        self._obs = obs
        self._saw = target_visible(obs)
        self._confirmed = False
        self._entered = self.env.in_success_region()
        self._forwards: deque[bool] = deque(maxlen=COLLISION_WINDOW)
        return self._publish(obs, None, None)

    @property
    def done(self) -> bool:
        return self.episode is not None and self.env.done

    def step(self) -> StepEvent:
        if self.episode is None:
            raise L3MVNError("no episode: reset first")
        if self.env.done:
            raise L3MVNError(f"episode {self.episode.key} is over: reset to start another")
        out = self.policy.act(self._obs)
        decision = out if isinstance(out, Decision) else Decision(action=Action.parse(out))
        obs = self.env.step(decision.action)
        if decision.action == Action.MOVE_FORWARD:
            self._forwards.append(obs.collided)
        self._saw = self._saw or target_visible(obs)
        self._confirmed = self._confirmed or decision.target_seen
        self._entered = self._entered or self.env.in_success_region()
        self._obs = obs
        if self.env.done:
            self._result = self._score()
        return self._publish(obs, decision, decision.action)

    def run(self) -> EpisodeResult:
        while not self.done:
            self.step()
        return self.result

    @property
    def result(self) -> EpisodeResult:
        if self._result is None:
            raise L3MVNError("the episode is still running")
        return self._result

    # --- interaction -------------------------------------------------------------------------
    def change_target(self, goal: str) -> StepEvent:
        """Keep walking from here toward a new target: a new segment of the same episode."""
        if self.episode is None or self.env.done:
            raise L3MVNError("no running episode to retarget")
        if goal not in self.env.scene.present_goals():
            raise L3MVNError(
                f"target {goal!r} is not in {self.env.scene.key}; present: {', '.join(self.env.scene.present_goals())}"
            )
        self.env.set_goal(goal)
        self.episode = replace(self.episode, goal=goal)
        self.segment += 1
        if hasattr(self.policy, "change_target"):
            self.policy.change_target(goal)
        self._obs = replace(self._obs, goal=goal)
        self._saw = target_visible(self._obs)
        self._confirmed = False
        self._entered = self.env.in_success_region()
        return self._publish(self._obs, None, None)

    # --- internals ---------------------------------------------------------------------------
    def _ground_truth(self) -> dict[str, float]:
        env = self.env
        return {
            "distance_to_goal_m": env.distance_to_goal(),
            "path_length_m": env.path_length_m,
            "shortest_path_m": env.shortest_path_length(),
            "in_success_region": float(env.in_success_region()),
        }

    def _publish(self, obs: Observation, decision: Decision | None, action: Action | None) -> StepEvent:
        assert self.episode is not None
        event = StepEvent(
            episode_key=self.episode.key, segment=self.segment, step=obs.step, goal=self.episode.goal,
            pose=obs.pose, observation=obs, decision=decision, action=action,
            ground_truth=self._ground_truth(), done=self.env.done,
            result=self._result.to_json() if self._result else None,
        )
        self.last_event = event
        self.bus.publish(event)
        return event

    def _score(self) -> EpisodeResult:
        env, ep = self.env, self.episode
        assert ep is not None
        f = self._forwards
        outcome = EpisodeOutcome(
            stopped=env.stopped, in_success_region=env.in_success_region(), steps=env.steps,
            path_length_m=env.path_length_m, shortest_path_m=env.shortest_path_length(),
            final_distance_m=env.distance_to_goal(), saw_target=self._saw, entered_region=self._entered,
            recent_collision_rate=(sum(f) / len(f)) if len(f) >= 10 else 0.0,
            agent_reported_stuck=bool(getattr(self.policy, "stuck", False)),
            coverage=self._coverage(),
        )
        success, spl, dtg, cause = score_episode(outcome)
        return EpisodeResult(
            key=ep.key, scene=ep.scene, floor=ep.floor, episode_id=ep.episode_id, goal=ep.goal,
            policy=self.policy_name, success=success, spl=spl, dtg=dtg, failure=cause, steps=env.steps,
            path_length_m=env.path_length_m, shortest_path_m=outcome.shortest_path_m, rule=env.cfg.success_rule,
            config_hash=self.config_hash, seconds=time.perf_counter() - self._t0,
            extra=self._extra(outcome),
        )

    def _extra(self, outcome: EpisodeOutcome) -> dict:
        extra: dict = {"segments": self.segment + 1} if self.segment else {}
        if outcome.coverage is not None:
            # Map-based agents: whether the map ever confirmed the target (>= target_min_cells), which
            # tells a target glimpsed but never confirmed from one confirmed but not reached.
            extra["coverage"] = round(outcome.coverage, 3)
            extra["confirmed"] = self._confirmed
        return extra

    def _coverage(self) -> float | None:
        """Ground truth for the failure analysis: the share of the floor reachable from the start
        that the agent's own map marks explored. None when the policy keeps no map or the backend
        has no ground-truth floor to measure against (``reachable_cells``, built-in simulator only)."""
        decision = self.last_event.decision if self.last_event is not None else None
        sem_map = decision.map if decision is not None else None
        reachable = getattr(self.env, "reachable_cells", None)
        if sem_map is None or self.episode is None or reachable is None:
            return None
        rows, cols = reachable(self.episode.start)
        xs, ys = self.env.scene.cell_center(rows, cols)
        return float(sem_map.explored_at(xs, ys).mean()) if len(rows) else None
