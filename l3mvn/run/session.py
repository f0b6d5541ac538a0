"""The navigation loop, one step at a time: environment + policy -> StepEvents on a bus.

The evaluator runs a session to the end; the dashboard steps one interactively, can change the target
mid-episode (a new, clearly marked segment) and hand the policy a manual long-term goal. The task
judges the episode from the simulator alone; what a policy says of itself (its Decisions) is kept
apart, as agent diagnostics, and never decides a failure cause.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Protocol, runtime_checkable

from l3mvn.agent.decision import Decision, GoalKind
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Action, EpisodeBrief, Observation
from l3mvn.run.events import EventBus, StepEvent
from l3mvn.world.episode import Episode
from l3mvn.world.sim.base import Environment
from l3mvn.world.task import EpisodeMeasures, EpisodeOutcome, EpisodeResult, ObjectNavTask, score_episode


class Policy(Protocol):
    """What the session drives: ``act`` returns an Action, or a Decision that explains itself."""

    def reset(self, episode: EpisodeBrief) -> None: ...

    def act(self, obs: Observation) -> Action | Decision: ...

    def change_target(self, goal: str) -> None: ...


@runtime_checkable
class Steerable(Protocol):
    """A policy that takes a researcher's commands mid-episode (the map-based agent)."""

    def set_manual_goal(self, cell: tuple[int, int] | None) -> None: ...

    def set_scorer(self, name: str) -> None: ...


@runtime_checkable
class Drivable(Protocol):
    """A policy whose next action a person gives (``teleop``)."""

    def drive(self, action: Action | int | str) -> None: ...


class EpisodeSession:
    """Drives one episode. Policies return an Action or a Decision (map-based agents explain
    themselves); every step is published on ``bus`` as a StepEvent. ``task`` judges it."""

    def __init__(
        self,
        env: Environment,
        task: ObjectNavTask,
        policy: Policy,
        *,
        policy_name: str,
        config_hash: str,
        bus: EventBus | None = None,
    ) -> None:
        self.env, self.task, self.policy = env, task, policy
        self.policy_name, self.config_hash = policy_name, config_hash
        self.bus = bus or EventBus()
        self.episode: Episode | None = None
        self.segment = 0
        self.last_event: StepEvent | None = None
        self._result: EpisodeResult | None = None
        # Seconds spent inside the environment's reset/step this episode, and rendering the frames it
        # returned (a frame is made as far as the agent and the task read it, while they read it).
        self.sim_seconds = 0.0

    # --- lifecycle ---------------------------------------------------------------------------
    def start(self, episode: Episode) -> StepEvent:
        self._t0 = time.perf_counter()
        self.episode, self.segment, self._result = episode, 0, None
        self.task.region(episode.goal)  # an absent goal is refused before the agent is placed
        t0 = time.perf_counter()
        obs = self.env.reset(episode)
        self.sim_seconds = time.perf_counter() - t0
        self.policy.reset(episode.brief)
        self._obs = obs
        self.measures = EpisodeMeasures(self.task, self.env, episode, obs)
        self.sim_seconds += obs.frame.take_render_seconds()
        self.diagnostics = AgentDiagnostics()
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
        self.sim_seconds += self._obs.frame.take_render_seconds()
        decision = out if isinstance(out, Decision) else Decision(action=Action.parse(out))
        t0 = time.perf_counter()
        obs = self.env.step(decision.action)
        self.sim_seconds += time.perf_counter() - t0
        self.measures.update(obs, decision.action)
        self.sim_seconds += obs.frame.take_render_seconds()
        if isinstance(out, Decision):
            self.diagnostics.update(out)
        self._obs = obs
        if self.env.done:
            self._result = self._score()
        return self._publish(obs, decision, decision.action)

    def run(self) -> EpisodeResult:
        while not self.done:
            self.step()
        return self.result

    def frontier_choices(self) -> Iterator[tuple[int, Decision]]:
        """Step to the episode's end, yielding (step number, decision) at every fresh choice among
        frontiers: a step whose long-term goal is a frontier, with frontiers extracted anew (between
        re-selections the agent keeps its list). What frontier data, PONI's walks and the benches
        that replay choices read."""
        step, last = 0, None
        while not self.done:
            decision = self.step().decision
            step += 1
            if decision is None or decision.goal_kind != GoalKind.FRONTIER or not decision.frontiers:
                continue
            if decision.frontiers is last:
                continue
            last = decision.frontiers
            yield step, decision

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
        scene = self.task.scene
        if goal not in scene.present_goals():
            raise L3MVNError(f"target {goal!r} is not in {scene.key}; present: {', '.join(scene.present_goals())}")
        self.task.region(goal)
        self.env.set_goal(goal)
        self.episode = replace(self.episode, goal=goal)
        self.segment += 1
        self.policy.change_target(goal)
        self._obs = replace(self._obs, goal=goal)
        self.measures.retarget(self.episode, self._obs)
        return self._publish(self._obs, None, None)

    def set_manual_goal(self, cell: tuple[int, int] | None) -> None:
        """Make a cell of the agent's map its long-term goal until reached (None clears it)."""
        if self.episode is None or self.env.done:
            raise L3MVNError("no running episode: reset first")
        self._steerable("manual goals").set_manual_goal(cell)

    def set_scorer(self, name: str) -> None:
        """Swap the language scorer of a language policy from the next frontier choice on."""
        self._steerable("a language scorer").set_scorer(name)

    def drive(self, action: Action | int | str) -> StepEvent:
        """One step with ``action`` chosen by hand (a ``Drivable`` policy only)."""
        if self.episode is None or self.env.done:
            raise L3MVNError("no running episode: reset first")
        if not isinstance(self.policy, Drivable):
            raise L3MVNError(f"policy {self.policy_name!r} is not driven by hand: pick policy teleop")
        self.policy.drive(action)
        return self.step()

    def _steerable(self, what: str) -> Steerable:
        if not isinstance(self.policy, Steerable):
            raise L3MVNError(f"policy {self.policy_name!r} takes no {what}: only map-based policies do")
        return self.policy

    # --- internals ---------------------------------------------------------------------------
    def _ground_truth(self) -> dict[str, float]:
        env, task, ep = self.env, self.task, self.episode
        assert ep is not None  # published only while an episode runs
        return {
            "distance_to_goal_m": task.distance_to_goal(env.pose, ep.goal),
            "path_length_m": env.path_length_m,
            "shortest_path_m": task.shortest_path_length(ep),
            "in_success_region": float(task.in_success_region(env.pose, ep.goal)),
        }

    def _publish(self, obs: Observation, decision: Decision | None, action: Action | None) -> StepEvent:
        assert self.episode is not None
        event = StepEvent(
            episode_key=self.episode.key,
            segment=self.segment,
            step=obs.step,
            goal=self.episode.goal,
            pose=obs.pose,
            observation=obs,
            decision=decision,
            action=action,
            ground_truth=self._ground_truth(),
            done=self.env.done,
            result=self._result.to_json() if self._result else None,
        )
        self.last_event = event
        self.bus.publish(event)
        return event

    def _score(self) -> EpisodeResult:
        env, ep = self.env, self.episode
        assert ep is not None
        outcome = self.measures.outcome()
        success, spl, dtg, cause = score_episode(outcome, self.task.cfg.task)
        return EpisodeResult(
            key=ep.key,
            scene=ep.scene,
            floor=ep.floor,
            episode_id=ep.episode_id,
            goal=ep.goal,
            policy=self.policy_name,
            success=success,
            spl=spl,
            dtg=dtg,
            failure=cause,
            steps=env.steps,
            path_length_m=env.path_length_m,
            shortest_path_m=outcome.shortest_path_m,
            rule=self.task.rule,
            config_hash=self.config_hash,
            seconds=time.perf_counter() - self._t0,
            extra=self._extra(outcome),
        )

    def _extra(self, outcome: EpisodeOutcome) -> dict:
        """The task's measures behind the failure cause (``coverage``: the share of the reachable floor
        the frames showed; ``confirmed``: the goal was in view well enough to confirm), and under
        ``agent`` what the policy reported of itself."""
        extra: dict = {"segments": self.segment + 1} if self.segment else {}
        extra["coverage"] = round(outcome.coverage, 3)
        extra["confirmed"] = self.measures.confirmed
        if self.diagnostics.decisions:
            extra["agent"] = self.diagnostics.to_json(self.task, self.episode)
        return extra


@dataclass
class AgentDiagnostics:
    """What a policy that explains itself reported about itself over an episode: whether it ever had
    a confirmed target as its goal, whether its planner was stuck at the end, and how much of the
    reachable floor its own map marks explored. Shown beside the task's measures, never used for them."""

    decisions: int = 0
    confirmed: bool = False
    stuck: bool = False
    last: Decision | None = None

    def update(self, decision: Decision) -> None:
        self.decisions += 1
        self.confirmed = self.confirmed or decision.target_seen
        self.stuck = decision.stuck
        self.last = decision

    def to_json(self, task: ObjectNavTask, episode: Episode | None) -> dict:
        out: dict = {"confirmed": self.confirmed, "stuck": self.stuck}
        sem_map = None if self.last is None else self.last.map
        if sem_map is not None and episode is not None:
            rows, cols = task.reachable_cells(episode.start)
            if len(rows):
                out["coverage"] = round(float(sem_map.explored_at(*task.scene.cell_center(rows, cols)).mean()), 3)
        return out
