"""Warm environments, tasks and policies per scene floor, and the sessions that run on them.

Building a floor's world costs 0.1-1 s and a language policy's models more, while an episode costs
seconds: eval workers, the dashboard and the bench scripts all keep floors warm, so they all get them
from here and cannot drift apart in how an episode is set up. Policies are reset per episode and
seed themselves from it, so a warm policy gives the same result as a fresh one.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

from l3mvn.core.config import Config
from l3mvn.run.events import EventBus
from l3mvn.run.registry import check_options, make_policy
from l3mvn.run.session import EpisodeSession
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.base import Environment
from l3mvn.world.sim.simulator import BuiltinSimulator
from l3mvn.world.task import EpisodeResult, ObjectNavTask

# Floors kept warm: eval workers take episodes in dataset order, so a handful covers what
# neighbouring workers are on without holding a whole split's worlds in memory.
WARM_FLOORS = 4


@dataclass
class Floor:
    """One scene floor, ready to run: its simulator, its task, and the policies built for it."""

    env: Environment
    task: ObjectNavTask
    policies: dict[str, object] = field(default_factory=dict)


class Runner:
    """Sessions on warm floors for any policy, under one config tree."""

    def __init__(self, config: Config, *, seed: int = 0, config_hash: str = "", warm_floors: int = WARM_FLOORS) -> None:
        self.config, self.seed, self.config_hash = config, seed, config_hash
        # A habitat floor is a server process holding a whole scan: one at a time.
        self.warm_floors = 1 if config.sim.backend == "habitat" else warm_floors
        self._floors: OrderedDict[str, Floor] = OrderedDict()

    def floor(self, scene: SceneMap) -> Floor:
        """The warm floor of ``scene`` (built on first use; the least recently used is dropped)."""
        if scene.key in self._floors:
            self._floors.move_to_end(scene.key)
        else:
            self._floors[scene.key] = Floor(make_environment(scene, self.config), ObjectNavTask(scene, self.config))
            while len(self._floors) > self.warm_floors:
                _close(self._floors.popitem(last=False)[1])
        return self._floors[scene.key]

    def close(self) -> None:
        """Close every warm floor's environment (a bridge's server process ends with it)."""
        while self._floors:
            _close(self._floors.popitem(last=False)[1])

    def policy(self, scene: SceneMap, name: str):
        """The warm policy ``name`` on ``scene``'s floor."""
        floor = self.floor(scene)
        if name not in floor.policies:
            check_options(name, self.config.policy)
            floor.policies[name] = make_policy(name, floor.env, floor.task, self.config, self.seed)
        return floor.policies[name]

    def session(
        self, scene: SceneMap, policy: str, bus: EventBus | None = None, *, config_hash: str | None = None
    ) -> EpisodeSession:
        """A session of ``policy`` on ``scene``'s floor, not yet started; ``config_hash`` overrides
        the runner's for a session whose settings differ (the dashboard's scorer choice)."""
        floor, agent = self.floor(scene), self.policy(scene, policy)
        return EpisodeSession(
            floor.env,
            floor.task,
            agent,
            policy_name=policy,
            bus=bus,
            config_hash=self.config_hash if config_hash is None else config_hash,
        )

    def run(self, scene: SceneMap, episode: Episode, policy: str, bus: EventBus | None = None) -> EpisodeResult:
        """Run one episode to the end and return its scored result."""
        session = self.session(scene, policy, bus)
        session.start(episode)
        return session.run()


def make_environment(scene: SceneMap, config: Config) -> Environment:
    """The simulator ``config.sim.backend`` names for one floor: ours in this process, or habitat-sim
    in the interpreter ``config.sim.habitat_python`` through the bridge (scans only)."""
    if config.sim.backend == "habitat":
        from l3mvn.world.sim.habitat_bridge import habitat_floor_environment

        return habitat_floor_environment(config.sim.habitat_python, scene, config.sim)
    return BuiltinSimulator(scene, config.sim)


def _close(floor: Floor) -> None:
    close = getattr(floor.env, "close", None)
    if close is not None:
        close()
