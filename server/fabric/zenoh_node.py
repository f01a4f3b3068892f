"""The fabric on Eclipse Zenoh: a peer session with explicit unicast endpoints (no scouting)."""

from __future__ import annotations

import json
from typing import Any

import zenoh

from server.fabric import Changes, FabricConfig, Handler, Kind, Presence, Unsubscribe


class ZenohFabric:
    """A Zenoh peer: listens on ``config.listen`` and connects to ``config.connect`` over TCP."""

    engine = "zenoh"

    def __init__(self, config: FabricConfig) -> None:
        conf = zenoh.Config()
        conf.insert_json5("mode", '"peer"')
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("listen/endpoints", json.dumps([f"tcp/{config.listen}"] if config.listen else []))
        conf.insert_json5("connect/endpoints", json.dumps([f"tcp/{c}" for c in config.connect]))
        self.session = zenoh.open(conf)
        self._keep: list[Any] = []

    def publisher(self, topic: str, kind: Kind, on_match: Presence | None = None) -> Handler:
        poses = kind is Kind.POSES
        pub = self.session.declare_publisher(
            topic,
            congestion_control=zenoh.CongestionControl.DROP if poses else zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.BEST_EFFORT if poses else zenoh.Reliability.RELIABLE,
            express=poses,  # do not batch a pose batch behind others: latency over throughput
        )
        self._keep.append(pub)
        if on_match is not None:
            told = Changes(on_match)
            self._keep.append(pub.declare_matching_listener(lambda status: told(status.matching)))
            status: Any = pub.matching_status  # (a MatchingStatus: zenoh 1.10's stub says bool)
            told(status.matching)  # the state now; the listener tells its changes
        return pub.put

    def subscribe(self, topic: str, kind: Kind, on_message: Handler) -> Unsubscribe:
        del kind  # the publisher sets the quality of service
        sub = self.session.declare_subscriber(topic, lambda s: on_message(s.payload.to_bytes()))
        self._keep.append(sub)

        def unsubscribe() -> None:
            if sub in self._keep:
                self._keep.remove(sub)
                sub.undeclare()

        return unsubscribe

    def announce(self, key: str) -> None:
        self._keep.append(self.session.liveliness().declare_token(key))

    def watch(self, key: str, on_change: Presence) -> None:
        def changed(sample: zenoh.Sample) -> None:
            on_change(sample.kind == zenoh.SampleKind.PUT)

        self._keep.append(self.session.liveliness().declare_subscriber(key, changed, history=True))

    def close(self) -> None:
        self._keep.clear()
        self.session.close()
