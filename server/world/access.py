"""Who may run which JCL command: every command of the JCL table has an *access* class, checked here.

* ``operator``: changes the world for everyone (loads, binds, files written, server-wide settings);
* ``soldier``: drives or reads one soldier, which must be the caller's own or shared (:mod:`.owners`);
* ``connection``: changes only the caller's connection (its STATUS period and throttle), or only answers it;
* ``read``: reads nothing private and changes nothing (accepted no-ops, library information).

The start-up script runs with no caller and may do everything.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from protocol.events import ROLES
from server.jcl import JclError

ACCESS_ROLE = {
    "connection": "observer",
    "read": "controller",
    "soldier": "controller",
    "operator": "operator",
}
_RANK = {role: k for k, role in enumerate(ROLES)}


@runtime_checkable
class Caller(Protocol):
    """A client running JCL (a session): its id, its granted role and its own settings."""

    client_id: str
    role: str

    def set_throttle(self, seconds: float) -> None: ...

    def set_report_interval(self, seconds: float) -> None: ...


def caller_of(caller: object | None) -> Caller | None:
    """The client behind a JCL call, or None for the server itself (the start-up script)."""
    return caller if isinstance(caller, Caller) else None


def check_access(command: str, access: str, caller: object | None) -> None:
    """JclError unless ``caller``'s role may run a command of this access class."""
    who = caller_of(caller)
    if who is None:
        return
    need = ACCESS_ROLE[access]
    if _RANK.get(who.role, -1) < _RANK[need]:
        raise JclError(f"{command}: needs the {need} role (this client is {who.role!r})")
