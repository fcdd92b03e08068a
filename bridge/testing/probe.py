"""The probe: a test's seat in a session's lock-step.

A test that drives a session (``bridge.testing.session``) adds one service of kind ``probe`` to it, served in the
test's own process (``run_session(hosted=...)``), not started as a process of its own. Each time it runs, the probe
hands the test what it sensed (every robot's true pose, LED, battery) and the records it heard since its last run (the
robots' logs, the services' logs, the session's events), then waits for the test's next command: the world waits with
it, so the test holds simulated time between its calls. The command says when the probe runs next and what it sends
(a stop), and the world goes on.

The probe is only ever driven by a test: started by ``swarm-sitl run``, its kind refuses to be built.
"""

from __future__ import annotations

import queue
from dataclasses import dataclass, field
from typing import Any

from bridge.core.plan import Plan
from bridge.core.services import Service, ServiceContext, ServiceSpec, service_entity

PROBE_NAME = "probe"  # its name in the session ([[services]]), so its process is svc-probe
PROBE_HEARS = ("/r*/log/*", "/svc/*/log/*", "/session/events", "/mavlink/to_gcs")


@dataclass
class Seen:
    """What the probe saw at one run: the time, the world's truth it senses, the records heard since its last run."""

    t_ns: int
    sensed: dict[str, Any]
    records: list[tuple[int, str, Any]] = field(default_factory=list)


@dataclass
class Go:
    """Run the world until ``wake_ns`` (the probe's next run; None: never again), sending ``out`` now."""

    wake_ns: int | None
    out: list[list[Any]] = field(default_factory=list)


class Ended:
    """The probe serves no more: the session is over (its duration, a stop, a failure)."""


class ProbeChannel:
    """The two queues between the probe (in the launcher's thread for it) and the test (its own thread)."""

    def __init__(self) -> None:
        self.seen: queue.SimpleQueue[Seen | Ended] = queue.SimpleQueue()
        self.commands: queue.SimpleQueue[Go] = queue.SimpleQueue()


class Probe(Service):
    """The probe service itself: reports what it sees, then blocks until the test's command."""

    def __init__(self, ctx: ServiceContext, channel: ProbeChannel) -> None:
        super().__init__(ctx)
        self.channel = channel
        self._heard: list[tuple[int, str, Any]] = []

    def on_record(self, t_ns: int, topic: str, values: Any) -> None:
        self._heard.append((t_ns, topic, values))

    def step(self, t_ns: int, datagrams: list[tuple[str, bytes]], sensed: dict[str, Any]) -> int | None:
        heard, self._heard = self._heard, []
        self.channel.seen.put(Seen(t_ns, sensed, heard))
        cmd = self.channel.commands.get()  # the world waits for this answer: the test holds simulated time
        self._out.extend(cmd.out)
        return cmd.wake_ns


class ProbeHost:
    """The participant host of the probe's process (``bridge.hosts.participant.Host``), served in the test's own
    process by the launcher."""

    def __init__(self, plan: Plan, channel: ProbeChannel) -> None:
        from bridge.hosts.service import service_context

        _, ctx = service_context(plan, PROBE_NAME)
        self.entity = service_entity(PROBE_NAME)
        self.probe = Probe(ctx, channel)
        self.channel = channel

    def run(self, ent: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        if ent != self.entity:
            raise KeyError(f"this process hosts {self.entity}, not {ent}")
        return self.probe.run(t_ns, inputs)

    def stats(self) -> dict[str, dict]:
        return {self.entity: {}}

    def stop(self) -> None:
        self.channel.seen.put(Ended())

    def ended(self) -> None:
        """Its process stopped serving (the launcher says so, after a stop or a failure): the test must not wait."""
        self.channel.seen.put(Ended())


def _refuse(ctx: ServiceContext) -> Service:
    raise RuntimeError(f"service {ctx.name!r} is of kind 'probe', which only a test drives (the swarm-sitl pytest "
                       "plugin's swarm_session fixture, or bridge.testing.SwarmSession); remove it from the config")


SPEC = ServiceSpec("probe", _refuse, senses=("poses", "robot_state", "radio"), hears=PROBE_HEARS,
                   hears_latest=("/r*/*/pins",),
                   title="a test's seat in the lock-step (bridge.testing)")
