"""Which transport serves a parsed remote address.

Kept apart from :mod:`.remotes` (addresses), which both transports import:
this module imports them, and nothing imports it back.
"""

from __future__ import annotations

from .remotes import Location


def open_remote(loc: Location):
    """The transport for ``loc``: a :class:`~.hub.HubRemote` or an :class:`~.fsremote.FsRemote`."""
    if loc.is_hub:
        from .hub import HubRemote

        return HubRemote(loc)
    from .fsremote import FsRemote

    return FsRemote(loc)
