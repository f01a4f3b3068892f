"""The fabric on Eclipse Cyclone DDS: unicast peers on a configured domain (no multicast).

A topic carries opaque bytes (``sequence<octet>``, the fastest type of the Python binding); '/' in a topic
name becomes '_'. A shard's pose blocks are topics of their own (``ttes_poses_K_B``), like Zenoh's keys: a
front-end's reader of a block it no longer watches is deleted, and no sample of it reaches the process.
Quality of service per :class:`~server.fabric.Kind`: poses best-effort keep-last-1, requests reliable
keep-all.

A node never hears its own samples (``IgnoreLocal.Participant``): a front-end both writes and reads
``ttes/fronts``, and Cyclone delivers a local sample synchronously inside ``write``, which waits for the
reader's listener while the binding holds the interpreter lock; a listener already running on DDS's receive
thread (another front-end's sample) waits for that lock, so the front-end hung for good
(``bench_scaleout.py --fabric dds --fronts 2``: the second front-end's clients created no soldiers). What a
node wrote to itself it dropped anyway.
"""

# no "from __future__ import annotations": cyclonedds resolves the IDL field types at class creation

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from cyclonedds.core import Listener, Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct, types
from cyclonedds.idl._machinery import BytesMachine, StructMachine
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from server.fabric import Changes, FabricConfig, Handler, Kind, Presence, Unsubscribe

if TYPE_CHECKING:
    Octets = bytes  # what the fields hold at run time (see _octets_as_bytes)
else:
    Octets = types.sequence[types.uint8]


@dataclass
class Blob(IdlStruct, typename="ttes.Blob"):
    """``struct Blob { sequence<octet> data; }``."""

    data: Octets


def _octets_as_bytes() -> None:
    """The binding (de)serialises ``sequence<octet>`` element by element into a Python list (about 0.1 s
    for a 1.3 MB batch); its ``bytes`` machine writes the same CDR (uint32 length, then the octets) in one
    copy, but ``bytes`` has no XTypes type object. So: declare the sequence, run the bytes machine."""
    idl = Blob.__idl__
    idl.populate()
    for machine in (idl.v1_machine, idl.v2_machine):
        assert isinstance(machine, StructMachine)
        machine.members_machines["data"] = BytesMachine()


_octets_as_bytes()


def unicast_xml(config: FabricConfig) -> str:
    """The CYCLONEDDS_URI of a loopback-or-LAN node: its peers are the hosts of listen and connect."""
    hosts = sorted(
        {e.rpartition(":")[0] or e for e in (config.listen, *config.connect) if e} or {"127.0.0.1"}
    )
    peers = "".join(f'<Peer address="{h}"/>' for h in hosts)
    return (
        "<CycloneDDS><Domain id='any'><General><AllowMulticast>false</AllowMulticast>"
        "<MaxMessageSize>65500B</MaxMessageSize></General>"
        "<Internal><SocketReceiveBufferSize min='8MB'/><SocketSendBufferSize min='8MB'/></Internal>"
        f"<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>60</MaxAutoParticipantIndex>"
        f"<Peers>{peers}</Peers></Discovery></Domain></CycloneDDS>"
    )


_QOS = {
    Kind.POSES: Qos(
        Policy.Reliability.BestEffort,
        Policy.History.KeepLast(1),
        Policy.Durability.Volatile,
        Policy.IgnoreLocal.Participant,
    ),
    Kind.REQUESTS: Qos(
        Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.History.KeepAll,
        Policy.IgnoreLocal.Participant,
    ),
}


_PRESENCE = Qos(
    Policy.Reliability.Reliable(duration(seconds=1)),
    Policy.Liveliness.Automatic(lease_duration=duration(seconds=1)),
)


class DdsFabric:
    """A DDS participant on ``config.domain``."""

    engine = "dds"

    def __init__(self, config: FabricConfig) -> None:
        os.environ.setdefault("CYCLONEDDS_URI", unicast_xml(config))
        self.participant = DomainParticipant(config.domain)
        self._topics: dict[str, Topic] = {}
        self._keep: list[Any] = []

    def _topic(self, name: str) -> Topic:
        if name not in self._topics:
            self._topics[name] = Topic(self.participant, name.replace("/", "_"), Blob)
        return self._topics[name]

    def publisher(self, topic: str, kind: Kind, on_match: Presence | None = None) -> Handler:
        listener = None
        if on_match is not None:
            told = Changes(on_match)
            listener = Listener(on_publication_matched=lambda _w, status: told(status.current_count > 0))
        writer = DataWriter(self.participant, self._topic(topic), qos=_QOS[kind], listener=listener)
        if on_match is not None:
            told(writer.get_publication_matched_status().current_count > 0)  # readers matched already
        self._keep.append(writer)
        return lambda data: writer.write(Blob(data))

    def subscribe(self, topic: str, kind: Kind, on_message: Handler) -> Unsubscribe:
        def available(reader: DataReader) -> None:
            for sample in reader.take(N=64):
                if isinstance(sample, Blob):  # not an InvalidSample (a writer's disposal)
                    on_message(sample.data)

        reader = DataReader(
            self.participant,
            self._topic(topic),
            qos=_QOS[kind],
            listener=Listener(on_data_available=available),
        )
        self._keep.append(reader)

        def unsubscribe() -> None:
            if reader in self._keep:
                self._keep.remove(reader)
                reader.__del__()  # deletes the reader now (the binding's __del__ then finds it gone)

        return unsubscribe

    def announce(self, key: str) -> None:
        """A writer with automatic liveliness on the key's own topic: its lease lapses when we die."""
        writer = DataWriter(self.participant, self._topic(key), qos=_PRESENCE)
        writer.write(Blob(b""))
        self._keep.append(writer)

    def watch(self, key: str, on_change: Presence) -> None:
        def changed(reader: DataReader, status: Any) -> None:
            on_change(status.alive_count > 0)

        listener = Listener(on_liveliness_changed=changed)
        self._keep.append(DataReader(self.participant, self._topic(key), qos=_PRESENCE, listener=listener))

    def close(self) -> None:
        self._keep.clear()
        self._topics.clear()
